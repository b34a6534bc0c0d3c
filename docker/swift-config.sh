#!/bin/sh
# OpenStack Swift all-in-one as an S3 store (issue 29): its configuration and rings written into a
# directory; used by the scale stack's swift container (docker/swift-entrypoint.sh) and by the tests
# that start Swift (tests/server/swift_s3.cc), so that both run the same Swift.
# Usage: swift-config.sh CONF_DIR DEVICES_DIR PROXY_PORT ACCOUNT_PORT CONTAINER_PORT OBJECT_PORT \
#          ACCESS_KEY SECRET_KEY
#   Four servers on 127.0.0.1, each one process run as the current user: the proxy on PROXY_PORT
#   with the s3api and tempauth middlewares (ACCESS_KEY is tempauth's ACCOUNT:USER, an admin of its
#   account, whose key is SECRET_KEY; signatures scoped to us-east-1), and one account, container
#   and object server keeping everything on the one device DEVICES_DIR/d1 (a plain directory whose
#   file system keeps user extended attributes). Rings of one partition and one replica. Also
#   CONF_DIR/netrc: the credentials for the curl tool (its --user splits at the first colon).
#   The rings come out the same for the same ports: rewriting them over kept data is safe.
set -eu
conf=$1
devices=$2
proxy_port=$3
account_port=$4
container_port=$5
object_port=$6
access_key=$7
secret_key=$8
account=${access_key%%:*}
user=${access_key#*:}
mkdir -p "$conf" "$devices/d1"

# This cluster's hash salt (fixed: the objects' places depend on it) and its one storage policy.
cat > "$conf/swift.conf" <<CONF
[swift-hash]
swift_hash_path_suffix = idms
swift_hash_path_prefix = idms
[storage-policy:0]
name = Policy-0
default = yes
CONF

# Each server in one process (workers = 0), on loopback, as this user, no mount check: the
# "device" is a plain directory.
common() {  # PORT: the [DEFAULT] section
  cat <<CONF
[DEFAULT]
bind_ip = 127.0.0.1
bind_port = $1
workers = 0
user = $(id -un)
swift_dir = $conf
devices = $devices
mount_check = false
disable_fallocate = true
log_level = INFO
CONF
}
for server in account:$account_port container:$container_port object:$object_port; do
  name=${server%:*}
  { common "${server#*:}"; printf '[pipeline:main]\npipeline = %s-server\n[app:%s-server]\nuse = egg:swift#%s\n' \
      "$name" "$name" "$name"; } > "$conf/$name-server.conf"
done

# The proxy: s3api just before tempauth (s3api checks the SigV4 signature's form and hands tempauth
# the key to verify), slo after them as s3api expects. tempauth keeps its tokens in memcache, which
# is not run: the cache middleware finds none and tempauth checks every S3 signature itself.
# location: the region the signatures are scoped to.
{ common "$proxy_port"; cat <<CONF; } > "$conf/proxy-server.conf"
[pipeline:main]
pipeline = catch_errors gatekeeper proxy-logging cache s3api tempauth slo proxy-logging proxy-server
[app:proxy-server]
use = egg:swift#proxy
account_autocreate = true
[filter:catch_errors]
use = egg:swift#catch_errors
[filter:gatekeeper]
use = egg:swift#gatekeeper
[filter:proxy-logging]
use = egg:swift#proxy_logging
[filter:cache]
use = egg:swift#memcache
memcache_servers = 127.0.0.1:1
[filter:s3api]
use = egg:swift#s3api
location = us-east-1
[filter:tempauth]
use = egg:swift#tempauth
user_${account}_${user} = $secret_key .admin
[filter:slo]
use = egg:swift#slo
CONF

# A ring per server of one partition, one replica, one device: everything on that server. Built
# with Swift's RingBuilder in one interpreter (what swift-ring-builder's create, add and rebalance
# do, in a fifth of the time: three rings cost 5.5 s through the command, 1.2 s so; each test
# starts its own Swift). Debian's python3, where python3-swift is.
/usr/bin/python3 - "$conf" "$account_port" "$container_port" "$object_port" <<'PY'
import sys
from swift.common.ring import RingBuilder
conf = sys.argv[1]
for name, port in zip(("account", "container", "object"), sys.argv[2:]):
    b = RingBuilder(0, 1, 1)
    b.add_dev({"region": 1, "zone": 1, "ip": "127.0.0.1", "port": int(port), "device": "d1", "weight": 1})
    b.rebalance()
    b.get_ring().save(f"{conf}/{name}.ring.gz")
PY

# The curl tool's credentials, readable by this user only.
printf 'machine 127.0.0.1 login %s password %s\n' "$access_key" "$secret_key" > "$conf/netrc"
chmod 0600 "$conf/netrc"
