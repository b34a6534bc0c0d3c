#!/bin/sh
# PostgreSQL 15 for the scale stack (docker/compose.scale.yaml): a cluster on the volume, made at
# the first start, listening on 127.0.0.1:$PGPORT with the database "idms". Loopback connections
# are trusted: the stack runs on one machine's loopback; anywhere else give the idms role a
# password (scram-sha-256 in pg_hba.conf) and the servers PGPASSWORD.
set -eu
port="${PGPORT:-5432}"
data=/var/lib/postgresql/data
bin=/usr/lib/postgresql/15/bin
if [ ! -s "$data/PG_VERSION" ]; then
  "$bin/initdb" -D "$data" -U postgres --auth=trust --encoding=UTF8 > /dev/null
  "$bin/pg_ctl" -D "$data" -o "-c listen_addresses=127.0.0.1 -p $port -k /tmp" -w start > /dev/null
  "$bin/psql" -h 127.0.0.1 -p "$port" -U postgres -qc "CREATE DATABASE idms" postgres
  "$bin/pg_ctl" -D "$data" -m fast -w stop > /dev/null
fi
exec "$bin/postgres" -D "$data" -c listen_addresses=127.0.0.1 -p "$port" -k /tmp
