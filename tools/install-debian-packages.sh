#!/usr/bin/env bash
# Installs those of the given Debian packages that are missing (apt-get, as root or through
# sudo), quietly when all are there. Shared by the bootstrap (./rayfarm) and the extra CI stages
# (tests/sanitize.sh, fuzz/run.sh, deploy/check.sh), so each lists only its packages.
#
#   tools/install-debian-packages.sh PACKAGE...
set -euo pipefail
missing=()
for p in "$@"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
printf 'installing Debian packages: %s\n' "${missing[*]}" >&2
sudo=()
[ "$(id -u)" -ne 0 ] && sudo=(sudo)
"${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq >&2
"${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
  "${missing[@]}" >&2
