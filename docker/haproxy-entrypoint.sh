#!/bin/sh
# HAProxy for the scale stack: its configuration from the environment (docker/haproxy-config.sh):
# $HAPROXY_PORT, and the idms-servers as "HOST:PORT ..." in $IDMS_SERVERS (agents and viewers).
set -eu
haproxy-config.sh "${HAPROXY_PORT:-8750}" "$IDMS_SERVERS" "$IDMS_SERVERS" > /tmp/haproxy.cfg
exec haproxy -db -f /tmp/haproxy.cfg
