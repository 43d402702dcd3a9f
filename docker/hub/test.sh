#!/usr/bin/env bash
# The hub test: the class's JupyterHub (docker/hub/up) on the private engine of
# docker/engine.sh, and a week of the class through it (docker/hub/loop.py).
#
#   docker/hub/test.sh            (as root; tests/system/test_hub.py runs it within `make test`)
#
# Steps: the engine (its own data root, the same cache as docker/test.sh, so the image that
# test built is reused); the base and snakekit's image (built only when missing or stale:
# compose build is quick when nothing changed); the hub's configuration checked against
# JupyterHub's, dockerspawner's and the authenticators' classes, for the default log-in
# (NativeAuthenticator) and for LTI 1.3 (check-config); the start command as docker/hub/README.md
# writes it (a single-node swarm, SwarmSpawner; it makes the instructor's and TA's accounts);
# the students' accounts from a roster (docker/hub/accounts); then loop.py: the refused log-ins,
# 25 students logging in at once (the time to a ready server for each), the kit's commands in
# every terminal, the instructor's and TA's commands as docker/hub/README.md gives them (grading
# through the hub's grading service; a student refused), the refusals and limits, one student's lesson 00 in
# headless Chromium through the hub's proxy (docker/browser-check), and that student's 3D view
# refused to another student (on the network and through the hub). On exit the engine stops and
# the host is checked and restored (engine_stop), as after docker/test.sh.
# Figures are printed on lines starting with "figure:". SNAKEKIT_HUB_BENCH=1 (bench/hub.py)
# adds the benchmark's: a cold start (the images out of the engine and loaded again from a
# gzip'd save; the build's cache of their last stages goes too), five warm spawns, and the hub and proxy
# under 50 users' requests.
set -uo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
cd "$ROOT"
VENV_BIN="$ROOT/${SNAKEKIT_VENV:-.venv}/bin"
STUDENTS=${SNAKEKIT_HUB_STUDENTS:-25}
# of them, how many submit lesson 06 for the TA to grade and return: grading is the grader's own
# suite's (tests/grader/), here the route through the hub (bench/hub.py: the whole class)
SUBMITTING=${SNAKEKIT_HUB_SUBMITTING:-6}  # 0: all
say() { echo "hub-test: $*"; }
figure() { echo "figure: $*"; }
die() { echo "hub-test: FAILED: $*" >&2; exit 1; }
[ "$(id -u)" = 0 ] || die "needs root (it starts its own dockerd)"
[ -x "$VENV_BIN/docker-compose" ] || die "docker-compose missing from $VENV_BIN; run 'make setup'"
# shellcheck source=docker/engine.sh
source "$ROOT/docker/engine.sh"
engine_packages || die "could not install docker.io, debootstrap, curl"
engine_lock 1800
finish() {
  local rc=$?
  [ -z "${RUN:-}" ] || [ ! -d "$RUN" ] || $DOCKER logs snakekit-hub > "$RUN/hub.log" 2>&1
  [ "$rc" = 0 ] || { say "the hub's log, last lines:"; grep -v ' 200 \| 30[12] ' "$RUN/hub.log" | tail -40 >&2; }
  engine_stop || rc=1
  [ -z "${RUN:-}" ] || rm -rf "$RUN"
  exit $rc
}
trap finish EXIT
trap 'exit 143' INT TERM
engine_on_stop() {
  $DOCKER rm -f snakekit-hub >/dev/null 2>&1
  local s; s=$($DOCKER service ls -q 2>/dev/null); [ -z "$s" ] || $DOCKER service rm $s >/dev/null 2>&1
  $DOCKER swarm leave --force >/dev/null 2>&1
  $DOCKER volume rm -f $($DOCKER volume ls -q --filter name=snakekit-) >/dev/null 2>&1
}
t_all=$(now)
engine_start
# a swarm left by an interrupted run: start from none
$DOCKER swarm leave --force >/dev/null 2>&1
engine_base
t=$(now)
engine_build snakekit-lab:latest "$RUN/build.log" || { tail -30 "$RUN/build.log" >&2; die "docker compose build lab failed"; }
"$VENV_BIN/docker-compose" -f docker/compose.yaml --profile grader build grader >>"$RUN/build.log" 2>&1 \
  || { tail -30 "$RUN/build.log" >&2; die "docker compose build grader failed"; }
say "snakekit's images (the students', the grader's) ready in $(since "$t") s"
figure "image: $(( $($DOCKER image inspect -f '{{.Size}}' snakekit-lab:latest) / 1000000 )) MB"
t=$(now)
if ! $DOCKER build --network host -f docker/hub/Dockerfile -t snakekit-hub:latest . >"$RUN/hub-build.log" 2>&1; then
  tail -30 "$RUN/hub-build.log" >&2
  die "the hub's image did not build"
fi
say "the hub's image ready in $(since "$t") s ($(( $($DOCKER image inspect -f '{{.Size}}' snakekit-hub:latest) / 1000000 )) MB)"

# the LTI configuration, against the authenticator's own classes (the hub's start checks the other)
SNAKEKIT_AUTH=lti SNAKEKIT_LTI_CLIENT_IDS=125900000000000001 \
  $DOCKER run --rm -e SNAKEKIT_AUTH -e SNAKEKIT_LTI_CLIENT_IDS snakekit-hub:latest python3 /srv/hub/check-config \
  | tee "$RUN/lti.txt" || die "the LTI configuration does not load"
grep -q "ltiauthenticator.lti13.auth.LTI13Authenticator" "$RUN/lti.txt" || die "the LTI authenticator was not the one loaded"

if [ -n "${SNAKEKIT_HUB_BENCH:-}" ]; then
  # The cold start (bench/hub.py): both images out of the engine (with the build's cache of their
  # last stages, which the next build makes again), then loaded from a compressed save, the bytes a node's pull
  # unpacks, without a registry or network; the first spawn below then starts from them.
  $DOCKER save snakekit-lab:latest snakekit-grader:latest | gzip -1 > "$RUN/images.tar.gz"
  $DOCKER image rm -f "$($DOCKER image inspect -f '{{.Id}}' snakekit-grader:latest)" >/dev/null
  $DOCKER image rm -f "$($DOCKER image inspect -f '{{.Id}}' snakekit-lab:latest)" >/dev/null
  kept=$($DOCKER system df --format '{{.Type}} {{.Size}}' | awk '$1 == "Images" {print $2}')
  t=$(now)
  $DOCKER load -q -i "$RUN/images.tar.gz" >/dev/null || die "docker load of the saved images failed"
  figure "cold: docker load of the two images from a gzip'd save ($(( $(stat -c %s "$RUN/images.tar.gz") / 1000000 )) MB; before it the engine kept $kept of images: the Debian base, the hub's image, the build's other stages): $(since "$t") s"
  rm -f "$RUN/images.tar.gz"
fi

# The old dummy log-in's shared password, left in the teacher's environment: the hub ignores it
# (loop.py tries it as the teacher, a student and a new name).
OLD_SHARED=week-of-class-$$
export SNAKEKIT_DUMMY_PASSWORD=$OLD_SHARED SNAKEKIT_HUB_BIND=127.0.0.1:18000
export SNAKEKIT_SUBMIT_LIMIT_MB=8 SNAKEKIT_EXCHANGE_QUOTA_MB=64 SNAKEKIT_MEM_LIMIT=768M SNAKEKIT_CPU_LIMIT=1
# bounds for a hang, not speeds: 25 servers starting at once on a busy 2-core machine take minutes
export SNAKEKIT_START_TIMEOUT=900 SNAKEKIT_HTTP_TIMEOUT=900
# The start command exactly as docker/hub/README.md gives it (the settings above in the environment)
start=$(awk '/^## Start it/ {f = 1} f && /^```sh$/ {getline; print; exit}' docker/hub/README.md)
[ "$start" = "SNAKEKIT_INSTRUCTORS=teacher,ta docker/hub/up" ] \
  || die "docker/hub/README.md's start command is '$start', not the instructors this test logs in as (teacher, ta)"
t=$(now)
bash -c "$start" 2>&1 | tee "$RUN/up.log"
[ "${PIPESTATUS[0]}" = 0 ] || die "$start failed"
figure "docker/hub/up to the hub answering: $(since "$t") s"
{ echo "username,password"
  sed -n 's/^hub: account \([^ ;]*\) made; first password: \([^ ]*\) .*/\1,\2/p' "$RUN/up.log"; } > "$RUN/passwords.csv"
[ "$(tail -n +2 "$RUN/passwords.csv" | cut -d, -f1 | tr '\n' ' ')" = "teacher ta " ] \
  || die "docker/hub/up did not make the instructor's and TA's accounts with a first password each: $(cat "$RUN/passwords.csv")"
# The students' accounts as the teacher makes them: from the roster (its column student)
{ echo "student,name"; for i in $(seq 1 "$STUDENTS"); do printf 's%02d,Student %d\n' "$i" "$i"; done; } > "$RUN/roster.csv"
docker/hub/accounts "$RUN/roster.csv" > "$RUN/students.csv" || die "docker/hub/accounts failed"
[ "$(tail -n +2 "$RUN/students.csv" | wc -l)" = "$STUDENTS" ] || die "docker/hub/accounts made $(tail -n +2 "$RUN/students.csv" | wc -l) accounts for $STUDENTS students"
tail -n +2 "$RUN/students.csv" >> "$RUN/passwords.csv"
say "accounts: teacher and ta made by docker/hub/up, $STUDENTS students' by docker/hub/accounts from the roster, a first password each"
# Lesson 00 in headless Chromium through the hub's proxy (docker/browser-check --hub-user: the
# student logs in on the hub's page), the 3D view drawn and moved; screenshots in artifacts/hub.
DOCKER=$DOCKER "$VENV_BIN/python" docker/hub/loop.py http://127.0.0.1:18000 --students "$STUDENTS" --submitting "$SUBMITTING" --browser "$ROOT/artifacts/hub" \
  --passwords "$RUN/passwords.csv" --old-shared-password "$OLD_SHARED" \
  --submit-limit-mb "$SNAKEKIT_SUBMIT_LIMIT_MB" ${SNAKEKIT_HUB_BENCH:+--bench} || die "the week on the hub failed"
figure "hub memory after the week: $($DOCKER stats --no-stream --format '{{.MemUsage}}' snakekit-hub)"
figure "the whole hub test: $(since "$t_all") s"
say "passed"
