#!/bin/sh
# HAProxy's configuration for several idms-servers (issue 29), printed to stdout; used by the
# scale stack's haproxy container (docker/compose.scale.yaml) and by the tests that start HAProxy
# (tests/server/scale_servers.cc), so that both run the same routing.
# Usage: haproxy-config.sh LISTEN_PORT "AGENT_HOST:PORT ..." "VIEWER_HOST:PORT ..." [BIND_HOST]
#   agents (/ws/agent) go to the least busy healthy server; everything else (viewers, REST) is
#   hashed by its path (the session id) over the viewer servers, consistently and with bounded
#   load (no server above 150% of the mean), so that one session's viewers meet on one server;
#   health checks on /api/health every 250 ms, a dead server's connections cut at once.
set -eu
port=$1
agents=$2
viewers=$3
bind=${4:-127.0.0.1}
cat <<CFG
global
  maxconn 4096
defaults
  mode http
  timeout connect 1s
  timeout client 30s
  timeout server 30s
  timeout tunnel 1h
  retries 3
  option redispatch 1
  default-server inter 250ms fall 2 rise 2 on-marked-down shutdown-sessions
frontend idms
  bind $bind:$port
  use_backend agents if { path_beg /ws/agent }
  default_backend viewers
backend agents
  balance leastconn
  option httpchk GET /api/health
CFG
i=0
for s in $agents; do echo "  server a$i $s check"; i=$((i + 1)); done
cat <<CFG
backend viewers
  balance uri
  hash-type consistent
  hash-balance-factor 150
  option httpchk GET /api/health
CFG
i=0
for s in $viewers; do echo "  server v$i $s check"; i=$((i + 1)); done
