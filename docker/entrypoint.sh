#!/bin/sh
# Serves /library when something is mounted there, else the built-in demo
# library. Extra arguments go to gmr-server. exec: signals reach the server,
# which stops gracefully on SIGTERM (docker stop).
set -e
if [ -n "$(ls -A /library 2>/dev/null)" ]; then
  exec gmr-server --library /library "$@"
fi
exec gmr-server "$@"
