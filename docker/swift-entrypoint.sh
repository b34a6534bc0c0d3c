#!/usr/bin/env bash
# OpenStack Swift all-in-one for the scale stack (docker/compose.scale.yaml): the S3 store of the
# idms-servers' blobs and recordings. Its configuration from the environment (docker/swift-config.sh)
# in /tmp/swift, its objects on the volume /srv/swift; the four servers are this script's children,
# it makes the bucket $SWIFT_BUCKET once the S3 API answers (idms-server refuses to start without
# it), and it exits when any server does, so that the container restarts whole.
# Environment: SWIFT_S3_PORT (the S3 endpoint), SWIFT_ACCOUNT_PORT, SWIFT_CONTAINER_PORT,
# SWIFT_OBJECT_PORT, SWIFT_BUCKET, and the credentials its clients are given, under the names they
# read: AWS_ACCESS_KEY_ID (tempauth's ACCOUNT:USER) and AWS_SECRET_ACCESS_KEY.
# `idms-swift-entrypoint health` (the HEALTHCHECK): whether the bucket answers the credentials.
set -euo pipefail
conf=/tmp/swift
port=${SWIFT_S3_PORT:-8080}
bucket=${SWIFT_BUCKET:-idms}

# CURL_ARGS... PATH: the HTTP status of an S3 request signed by curl itself (SigV4, with the
# credentials swift-config.sh wrote for it), 000 when nothing answers.
s3() {
  local path=${*: -1}
  curl -s -o /dev/null -w '%{http_code}' --max-time 5 --aws-sigv4 aws:amz:us-east-1:s3 \
    --netrc-file "$conf/netrc" -H 'x-amz-content-sha256: UNSIGNED-PAYLOAD' "${@:1:$#-1}" \
    "http://127.0.0.1:$port$path" || true
}
if [ "${1:-}" = health ]; then
  [ "$(s3 --head "/$bucket")" = 200 ]
  exit
fi

swift-config.sh "$conf" /srv/swift "$port" "${SWIFT_ACCOUNT_PORT:-6012}" "${SWIFT_CONTAINER_PORT:-6011}" \
  "${SWIFT_OBJECT_PORT:-6010}" "${AWS_ACCESS_KEY_ID:?}" "${AWS_SECRET_ACCESS_KEY:?}"
# -v: each server's log on the console, i.e. the container's log.
pids=()
for server in account container object proxy; do
  "swift-$server-server" "$conf/$server-server.conf" -v &
  pids+=($!)
done
stop() { kill "${pids[@]}" 2> /dev/null || true; wait; }
trap 'stop; exit 0' TERM INT

# The bucket: 404 until it is made, 200 once it is (at once when the volume holds it).
status=000
for _ in $(seq 240); do  # 60 s
  status=$(s3 --head "/$bucket")
  [ "$status" = 200 ] && break
  [ "$status" = 404 ] && s3 -X PUT "/$bucket" > /dev/null
  sleep 0.25
done
if [ "$status" != 200 ]; then
  echo "idms-swift-entrypoint: bucket $bucket on 127.0.0.1:$port: HTTP $status after 60 s" >&2
  stop
  exit 1
fi
echo "idms-swift-entrypoint: S3 on 127.0.0.1:$port, bucket $bucket" >&2

# Any server gone: the others too, and the container with them.
code=0
wait -n || code=$?
echo "idms-swift-entrypoint: a Swift server exited (status $code); stopping" >&2
stop
exit 1
