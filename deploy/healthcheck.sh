#!/bin/sh
# The image's HEALTHCHECK (deploy/Dockerfile installs this as /usr/local/bin/rayfarm-healthcheck).
# One image serves both roles, so the check looks at what PID 1 runs:
#   rayfarm coordinator ...  asks the coordinator's own gRPC health service, at
#                            $RAYFARM_HEALTH_ADDR (default 127.0.0.1:7071: run it with
#                            --health-listen 0.0.0.0:7071, the plaintext health-only port that
#                            stays plaintext when the main port serves TLS);
#   rayfarm worker ...       checks the worker itself, never the coordinator: the age of the
#                            heartbeat file it rewrites while its loops turn
#                            ($RAYFARM_HEARTBEAT_FILE, which the image sets) must be under
#                            $RAYFARM_HEARTBEAT_MAX_AGE seconds (default 120).
# Exit 0 healthy, 1 unhealthy, with the reason on stdout (docker inspect shows it).
set -eu
role=$(tr '\0' '\n' </proc/1/cmdline | sed -n 2p)
case "$role" in
  coordinator)
    # Plaintext whatever RAYFARM_TLS_CA says: the health-only port never serves TLS.
    exec env -u RAYFARM_TLS_CA rayfarm health "${RAYFARM_HEALTH_ADDR:-127.0.0.1:7071}"
    ;;
  worker)
    file=${RAYFARM_HEARTBEAT_FILE:-}
    if [ -z "$file" ] || [ ! -f "$file" ]; then
      echo "worker: no heartbeat file '${file}' yet"
      exit 1
    fi
    age=$(($(date +%s) - $(stat -c %Y "$file")))
    if [ "$age" -ge "${RAYFARM_HEARTBEAT_MAX_AGE:-120}" ]; then
      echo "worker: heartbeat $file is $age s old"
      exit 1
    fi
    echo "worker: heartbeat $age s ago"
    ;;
  *)
    echo "not a long-running role ('$role'): nothing to check"
    ;;
esac
