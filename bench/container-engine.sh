#!/usr/bin/env bash
# Runs a command (bench/container.py) with the private Docker engine of docker/engine.sh up and
# the image snakekit-lab built (or reused from the engine's cache; with SNAKEKIT_BENCH_ROS=1 the
# ROS image snakekit-ros too, as bench/ros.py needs), as docker/test.sh does; then
# always stops the engine and restores the host's iptables, ip_forward and bridge state.
#
#   bench/container-engine.sh COMMAND [ARG...]     (as root, with Debian's docker.io installed)
#
# The command sees DOCKER_HOST, SNAKEKIT_DOCKER (Debian's client), SNAKEKIT_COMPOSE (compose
# v2 from the venv) and SNAKEKIT_BENCH_ENGINE (JSON: the engine's start and the build's time).
# Exit status: the command's, or 1 when the engine could not be started or the host not restored.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
VENV_BIN="$ROOT/${SNAKEKIT_VENV:-.venv}/bin"
IMAGE=${SNAKEKIT_IMAGE:-snakekit-lab:latest}

say() { echo "bench-engine: $*" >&2; }
figure() { say "$*"; }
die() { echo "bench-engine: FAILED: $*" >&2; exit 1; }
# shellcheck source=docker/engine.sh
source "$ROOT/docker/engine.sh"

[ "$(id -u)" = 0 ] || die "needs root to start dockerd"
command -v dockerd >/dev/null && [ -x /usr/bin/docker ] || die "Debian's docker.io is not installed (tools/setup installs it)"
[ -x "$VENV_BIN/docker-compose" ] || die "docker-compose missing from $VENV_BIN; run 'make setup'"
engine_lock "${SNAKEKIT_ENGINE_WAIT:-600}"

trap 'engine_exit >&2' EXIT  # the command's standard output stays its own
trap 'exit 130' INT TERM

engine_start
engine_base
t=$(now)
if [ "${SNAKEKIT_BENCH_BUILD:-1}" = 1 ] || ! $DOCKER image inspect "$IMAGE" >/dev/null 2>&1; then
  engine_build "$IMAGE" "$RUN/build.log" || { tail -30 "$RUN/build.log" >&2; die "docker build failed"; }
  built=1
else
  built=0
fi
build_s=$(since "$t")
say "image $IMAGE $([ "$built" = 1 ] && echo "built in $build_s s ($([ "$ENGINE_COLD" = 1 ] && echo cold || echo "warm cache"))" || echo reused)"
if [ "${SNAKEKIT_BENCH_ROS:-0}" = 1 ]; then  # bench/ros.py: the ROS image too, FROM the students' (docs/ros.md)
  t=$(now)
  (cd "$ROOT" && "$VENV_BIN/docker-compose" -f docker/compose.yaml --profile ros build roscore) >"$RUN/build-ros.log" 2>&1 \
    || { tail -30 "$RUN/build-ros.log" >&2; die "docker compose --profile ros build failed"; }
  say "image snakekit-ros:latest built in $(since "$t") s"
fi

export SNAKEKIT_DOCKER=$DOCKER SNAKEKIT_COMPOSE="$VENV_BIN/docker-compose" SNAKEKIT_IMAGE=$IMAGE
export SNAKEKIT_BENCH_ENGINE="{\"engine_start_s\": $ENGINE_START_S, \"build_s\": $build_s, \"built\": $built, \"cold\": $ENGINE_COLD}"
set +e
"$@"
rc=$?
set -e
exit "$rc"
