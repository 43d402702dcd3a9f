#!/usr/bin/env bash
# The Binder test: jupyter-repo2docker builds the repository as mybinder.org does, on the
# private Docker engine of docker/engine.sh, then the image is started with repo2docker's own
# command (`jupyter notebook ... --NotebookApp.default_url=/lab`, as Binder starts it) and a
# lesson is opened: the server lands on the lessons and serves none of nbgrader's teacher tools,
# lesson 00's kernel runs a cell, and headless Chromium opens the lesson in JupyterLab (no
# teacher's tools in the page either) and runs that cell from the page
# (screenshot in artifacts/).
#
#   binder/test.sh            (as root; tests/system/test_binder.py runs it within `make test`)
#
# repo2docker finds binder/Dockerfile, a link to docker/Dockerfile (its Dockerfile route), so
# Binder builds the same image as `docker compose build lab`; its buildpacks (environment.yml,
# requirements.txt) start from buildpack-deps on Docker Hub and install conda, which the
# Dockerfile route needs neither of. On the engine that docker/test.sh has used, every layer
# comes from its cache. The engine has no default bridge, so the build's downloads use the
# host's network (repo2docker's extra_build_kwargs, as compose.yaml's `network: host`).
# Figures are printed on lines starting with "figure:".
#
# Cache: ${SNAKEKIT_CACHE:-~/.cache/snakekit}, the engine's data root shared with docker/test.sh.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
VENV_BIN="$ROOT/${SNAKEKIT_VENV:-.venv}/bin"
IMAGE=snakekit-binder:test

say() { echo "binder-test: $*"; }
figure() { echo "figure: $*"; }
die() { echo "binder-test: FAILED: $*" >&2; exit 1; }
# shellcheck source=docker/engine.sh
source "$ROOT/docker/engine.sh"

[ "$(id -u)" = 0 ] || die "needs root (apt-get, dockerd); run it as root, e.g. sudo binder/test.sh"
[ -x "$VENV_BIN/jupyter-repo2docker" ] || die "jupyter-repo2docker missing from $VENV_BIN; run 'make setup'"
[ -L binder/Dockerfile ] && [ "$(readlink binder/Dockerfile)" = ../docker/Dockerfile ] \
  || die "binder/Dockerfile must be a link to ../docker/Dockerfile (Binder builds the container's image)"
engine_packages || die "could not install docker.io, debootstrap, curl"
engine_lock 1800

trap engine_exit EXIT
trap 'exit 130' INT TERM

engine_start
engine_base

# --- build: repo2docker --no-run, as BinderHub calls it ----------------------------------------
cat > "$RUN/repo2docker_config.py" <<'EOF'
c.Repo2Docker.extra_build_kwargs = {"network_mode": "host"}
EOF
t=$(now)
"$VENV_BIN/jupyter-repo2docker" --config "$RUN/repo2docker_config.py" --no-run --image-name "$IMAGE" \
  --user-id 1000 --user-name jovyan "$ROOT" >"$RUN/build.log" 2>&1 \
  || { tail -40 "$RUN/build.log" >&2; die "repo2docker failed to build the repository"; }
build_s=$(since "$t")
grep -q "Using DockerBuildPack builder" "$RUN/build.log" \
  || { tail -20 "$RUN/build.log" >&2; die "repo2docker did not take the Dockerfile route"; }
cached=$(grep -c -- '---> Using cache' "$RUN/build.log" || true)
steps=$(grep -c -E '^Step [0-9]+/' "$RUN/build.log" || true)
figure "repo2docker build: $build_s s ($cached of $steps steps from the engine's cache; $("$VENV_BIN/jupyter-repo2docker" --version))"
figure "repo2docker image: $(( $($DOCKER image inspect -f '{{.Size}}' "$IMAGE") / 1000000 )) MB"

# --- run it as repo2docker and Binder do, and open a lesson ----------------------------------
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
TOKEN=$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')
$DOCKER network create snakekit-binder-run >/dev/null
t=$(now)
$DOCKER run -d --rm --name snakekit-binder-run --network snakekit-binder-run -p "127.0.0.1:$port:8888" \
  -e JUPYTER_TOKEN="$TOKEN" "$IMAGE" \
  jupyter notebook --ip=0.0.0.0 --port=8888 "--NotebookApp.custom_display_url=http://127.0.0.1:$port" \
  --NotebookApp.default_url=/lab 2>&1 >/dev/null | grep -v "IPv4 forwarding is disabled" >&2 || true
engine_on_stop() { $DOCKER rm -f snakekit-binder-run >/dev/null 2>&1; $DOCKER network rm snakekit-binder-run >/dev/null 2>&1; }
"$VENV_BIN/python" "$ROOT/binder/open-lesson" "http://127.0.0.1:$port" "$TOKEN" --browser "$ROOT/artifacts" \
  || { $DOCKER logs snakekit-binder-run 2>&1 | tail -30 >&2; die "the lesson did not open in the Binder image"; }
figure "repo2docker image: docker run to lesson 00 opened and its first cell run (API and Chromium) in $(since "$t") s"
say "passed"
