#!/usr/bin/env bash
# Static checks of deploy/ that need no cluster (CI runs this; docs/deploy.md):
#   - the Slurm scripts parse (bash -n) and pass shellcheck.
# (The Slurm coordinator-less mode also runs for real in tests/deploy_test.cpp.)
# Installs what it needs from Debian. Budget on the 2-core CI machine: under a minute.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
log() { printf 'deploy-check: %s\n' "$*" >&2; }

"$ROOT/tools/install-debian-packages.sh" shellcheck

status=0
for f in "$ROOT"/deploy/slurm/*.sbatch "$ROOT"/deploy/check.sh "$ROOT"/tools/*.sh; do
  bash -n "$f" || { log "$f does not parse"; status=1; }
  shellcheck "$f" || { log "$f: shellcheck findings above"; status=1; }
done
[ $status -eq 0 ] && log "Slurm scripts: bash -n and shellcheck clean"
exit $status
