#!/usr/bin/env bash
# Installs those of the given Debian packages that are missing (apt-get, as root or through
# sudo), quietly when all are there. Shared by the bootstrap (./rayfarm) and the extra CI stages
# (tests/sanitize.sh, fuzz/run.sh, deploy/check.sh), so each lists only its packages.
#
#   tools/install-debian-packages.sh PACKAGE...
#   tools/install-debian-packages.sh --check PACKAGE...   only says which are missing (exit 1)
set -euo pipefail
check_only=0
if [ "${1:-}" = "--check" ]; then
  check_only=1
  shift
fi
missing=()
for p in "$@"; do
  # No pipe into `grep -q`: under pipefail, grep exiting early would fail dpkg-query (SIGPIPE).
  status=$(dpkg-query -W -f='${Status}' "$p" 2>/dev/null || true)
  [[ "$status" == *"install ok installed"* ]] || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$check_only" -eq 1 ]; then
  printf 'missing Debian packages: %s
install them with: sudo apt-get install %s
' \
    "${missing[*]}" "${missing[*]}" >&2
  exit 1
fi
printf 'installing Debian packages: %s\n' "${missing[*]}" >&2
sudo=()
[ "$(id -u)" -ne 0 ] && sudo=(sudo)
"${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq >&2
"${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
  "${missing[@]}" >&2
