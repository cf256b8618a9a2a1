#!/bin/sh
# gmr-server in a container (docs/security.md, "Docker"):
# - serves $GMR_LIBRARY_DIR (/library) when something is mounted there, else
#   the built-in demo library;
# - listens on $GMR_BIND (default 0.0.0.0: inside a container, the published
#   port, `-p 127.0.0.1:7400:7400` or `-p 7400:7400`, decides who reaches it);
# - uses the secrets mounted in $GMR_SECRETS_DIR (/run/secrets): gmr-auth (the
#   auth file), gmr-tls-cert with gmr-tls-key (TLS).
# Arguments go to gmr-server; a flag given there replaces the one made here.
# exec: signals reach the server, which stops gracefully on SIGTERM.
set -e
library=${GMR_LIBRARY_DIR:-/library}
secrets=${GMR_SECRETS_DIR:-/run/secrets}

given() {  # given FLAG ARGS...: is FLAG among ARGS?
  flag=$1
  shift
  for a in "$@"; do
    case $a in "$flag" | "$flag"=*) return 0 ;; esac
  done
  return 1
}

if ! given --tls-cert "$@" && [ -f "$secrets/gmr-tls-cert" ] && [ -f "$secrets/gmr-tls-key" ]; then
  set -- --tls-cert "$secrets/gmr-tls-cert" --tls-key "$secrets/gmr-tls-key" "$@"
fi
if ! given --auth-file "$@" && [ -f "$secrets/gmr-auth" ]; then
  set -- --auth-file "$secrets/gmr-auth" "$@"
fi
if ! given --library "$@" && [ -n "$(ls -A "$library" 2>/dev/null)" ]; then
  set -- --library "$library" "$@"
fi
if ! given --bind "$@"; then
  set -- --bind "${GMR_BIND:-0.0.0.0}" "$@"
fi
exec gmr-server "$@"
