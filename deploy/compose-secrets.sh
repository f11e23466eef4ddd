#!/usr/bin/env bash
# Makes deploy/secrets/ for deploy/compose.yaml: a worker token and a client token (with the
# coordinator's token file accepting both), and a private CA with a certificate for the
# coordinator (names: coordinator, localhost, 127.0.0.1) and its key. Refuses to overwrite.
#   deploy/compose-secrets.sh [TENANT]     (TENANT of the client token; default: default)
# Uses the rayfarm binary ($RAYFARM, default ./rayfarm from the repository) and openssl.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DIR="$ROOT/deploy/secrets"
RAYFARM="${RAYFARM:-$ROOT/rayfarm}"
tenant="${1:-default}"
if [ -e "$DIR/tokens" ]; then
  echo "compose-secrets: $DIR/tokens exists; remove $DIR to make new secrets" >&2
  exit 1
fi
mkdir -p "$DIR"
umask 077
"$RAYFARM" token new --role worker --tenant farm >"$DIR/worker.new"
"$RAYFARM" token new --role client --tenant "$tenant" >"$DIR/client.new"
sed -n 1p "$DIR/worker.new" >"$DIR/worker.token"
sed -n 1p "$DIR/client.new" >"$DIR/client.token"
{ sed -n 2p "$DIR/worker.new"; sed -n 2p "$DIR/client.new"; } >"$DIR/tokens"
rm "$DIR/worker.new" "$DIR/client.new"

openssl req -x509 -newkey rsa:3072 -nodes -days 3650 -subj "/CN=rayfarm compose CA" \
  -keyout "$DIR/ca.key" -out "$DIR/ca.crt" 2>/dev/null
openssl req -newkey rsa:3072 -nodes -subj "/CN=coordinator" \
  -keyout "$DIR/tls.key" -out "$DIR/tls.csr" 2>/dev/null
printf 'subjectAltName=DNS:coordinator,DNS:localhost,IP:127.0.0.1\n' >"$DIR/san.ext"
openssl x509 -req -in "$DIR/tls.csr" -CA "$DIR/ca.crt" -CAkey "$DIR/ca.key" -CAcreateserial \
  -days 825 -extfile "$DIR/san.ext" -out "$DIR/tls.crt" 2>/dev/null
rm "$DIR/tls.csr" "$DIR/san.ext"

# Compose mounts secret files with their owner and mode: the image's user (10001) must read
# them. As root, give them to it; otherwise they must be world-readable on this host.
if [ "$(id -u)" -eq 0 ]; then
  chown 10001:10001 "$DIR/tokens" "$DIR/worker.token" "$DIR/tls.crt" "$DIR/tls.key" "$DIR/ca.crt"
else
  chmod 0644 "$DIR/tokens" "$DIR/worker.token" "$DIR/tls.crt" "$DIR/tls.key" "$DIR/ca.crt"
  echo "compose-secrets: not root, so the secrets the containers read are world-readable" >&2
fi
echo "compose-secrets: wrote $DIR (client token: $DIR/client.token, CA: $DIR/ca.crt)" >&2
