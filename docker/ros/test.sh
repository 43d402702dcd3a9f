#!/usr/bin/env bash
# The ROS test: compose's `ros` profile (the study's multi-container set-up on our arm) on the
# private engine of docker/engine.sh, checked as a user meets it.
#
#   docker/ros/test.sh            (as root; tests/system/test_ros_compose.py runs it within `make test`)
#
# Steps: the engine (its own data root, the same cache as docker/test.sh, so the students' image
# that test built is reused); the base and the students' image (built only when missing or
# stale); hadolint docker/ros/Dockerfile; compose.yaml valid with the profile; the ROS image
# built with the user's command (`docker compose --profile ros build`), its size and what it adds
# to the students' image; the arm's service started alone first (it waits for roscore); then
# `docker compose --profile ros up -d` as docs/ros.md gives it, the
# printed URL; RViz in noVNC in headless Chromium with the arm at home (docker/ros/rviz-check:
# the arm drawn); then, inside the stack, a small node in the arm's container
# (docker/ros/check-stack.py): a folding goal refused on /rosout with nothing moving, the Task 2
# sweep (shortened) followed by /joint_states as the kit's own simulator runs it, `rosbag play`
# of a kit .bag publishing its joint states, and the arm left in another pose; RViz screenshotted
# again (the arm drawn, its links elsewhere); `rostopic echo` and `rosbag record` from a terminal
# (`exec arm bash`), the bag copied out as docs/ros.md says; docs/ros.md's `rostopic pub` of the
# sweep, run to its end; `down`: no container, network or volume left of the profile. On exit the
# engine stops and the host is checked and restored (engine_stop), as after docker/test.sh.
# Screenshots in artifacts/ros/. Figures on lines starting with "figure:".
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
cd "$ROOT"
VENV_BIN="$ROOT/${SNAKEKIT_VENV:-.venv}/bin"
PROJECT=snakekit-ros-test
HANG=${SNAKEKIT_ROS_HANG:-180}  # [s] a bound for each wait on a busy machine (a quiet one: a few s)
SHOTS="$ROOT/artifacts/ros"
say() { echo "ros-test: $*"; }
figure() { echo "figure: $*"; }
die() { echo "ros-test: FAILED: $*" >&2; exit 1; }
[ "$(id -u)" = 0 ] || die "needs root (apt-get, dockerd); run it as root, e.g. sudo docker/ros/test.sh"
[ -x "$VENV_BIN/hadolint" ] && [ -x "$VENV_BIN/docker-compose" ] \
  || die "hadolint or docker-compose missing from $VENV_BIN; run 'make setup'"
# shellcheck source=docker/engine.sh
source "$ROOT/docker/engine.sh"
engine_packages || die "could not install docker.io, debootstrap, curl"
COMPOSE=("$VENV_BIN/docker-compose" -p "$PROJECT" -f "$ROOT/docker/compose.yaml" --profile ros)
engine_lock 1800
engine_on_stop() { "${COMPOSE[@]}" down --volumes --remove-orphans >/dev/null 2>&1; }
trap engine_exit EXIT
trap 'exit 130' INT TERM
t_all=$(now)
engine_start
engine_base

# --- lint, validate, build ----------------------------------------------------------------
"$VENV_BIN/hadolint" docker/ros/Dockerfile || die "hadolint found problems in docker/ros/Dockerfile"
"${COMPOSE[@]}" config -q || die "compose.yaml is invalid with the ros profile"
services=$("${COMPOSE[@]}" config --services | sort | tr '\n' ' ')
[ "$services" = "arm lab roscore rviz state-publisher " ] || die "the ros profile's services: $services"
say "hadolint: docker/ros/Dockerfile is clean; compose.yaml is valid with the ros profile ($services)"
t=$(now)
engine_build snakekit-lab:latest "$RUN/build-lab.log" || { tail -30 "$RUN/build-lab.log" >&2; die "docker compose build lab failed"; }
lab_s=$(since "$t")
t=$(now)
"${COMPOSE[@]}" build >"$RUN/build-ros.log" 2>&1 || { tail -40 "$RUN/build-ros.log" >&2; die "docker compose --profile ros build failed"; }
figure "build: the students' image $lab_s s, then the ROS image $(since "$t") s ($([ "$ENGINE_COLD" = 1 ] && echo "cold: empty engine cache" || echo "engine cache kept"))"
ros_size=$($DOCKER image inspect -f '{{.Size}}' snakekit-ros:latest)
lab_size=$($DOCKER image inspect -f '{{.Size}}' snakekit-lab:latest)
# the ROS image is the students' plus its own layers (the kit and its venv shared, not copied)
lab_layers=$($DOCKER image inspect -f '{{join .RootFS.Layers " "}}' snakekit-lab:latest)
ros_layers=$($DOCKER image inspect -f '{{join .RootFS.Layers " "}}' snakekit-ros:latest)
[ "${ros_layers#"$lab_layers"}" != "$ros_layers" ] || die "the ROS image is not built on the students' image's layers"
gb() { awk -v b="$1" 'BEGIN { printf "%.2f", b / 1e9 }'; }
figure "ROS image $(gb "$ros_size") GB (snakekit-lab $(gb "$lab_size") GB; $(( (ros_size - lab_size) / 1000000 )) MB added: Debian's ROS 1, RViz, Xvfb, x11vnc, noVNC) (target <= 1.5 GB)"
[ "$ros_size" -le 1500000000 ] || die "the ROS image is $(gb "$ros_size") GB, above the 1.5 GB target"

# --- up, as docs/ros.md gives it ----------------------------------------------------------------
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
export SNAKEKIT_ROS_PORT SNAKEKIT_LAB_PORT
SNAKEKIT_ROS_PORT=$(free_port)
SNAKEKIT_LAB_PORT=$(free_port)  # (the lab, which has no profile, comes up beside the ROS services)
URL="http://127.0.0.1:$SNAKEKIT_ROS_PORT"
# the arm first, without the master (--no-deps): it must wait for roscore, not die
"${COMPOSE[@]}" up -d --no-deps arm >"$RUN/up-arm.log" 2>&1 || { cat "$RUN/up-arm.log" >&2; die "up arm failed"; }
arm_id=$("${COMPOSE[@]}" ps -q arm)
sleep 5
[ "$($DOCKER inspect -f '{{.State.Running}} {{.RestartCount}}' "$arm_id")" = "true 0" ] \
  || die "the arm's node, started before roscore, did not wait for it: $("${COMPOSE[@]}" logs arm 2>&1 | tail -5)"
t=$(now)
"${COMPOSE[@]}" up -d >"$RUN/up.log" 2>&1 || { cat "$RUN/up.log" >&2; die "docker compose --profile ros up failed"; }
printed=""
until printed=$("${COMPOSE[@]}" logs rviz 2>/dev/null | grep -o "open http://[^ ]*" | head -1) && [ -n "$printed" ]; do
  [ "$(since "$t" | cut -d. -f1)" -lt "$HANG" ] || die "the rviz service printed no URL within $HANG s: $("${COMPOSE[@]}" logs rviz 2>&1 | tail -5)"
  sleep 0.2
done
[ "$printed" = "open $URL/vnc.html?autoconnect=1&resize=scale" ] || die "the rviz service prints '$printed'"
until curl -s --max-time 2 "$URL/vnc.html" | grep -q noVNC; do
  [ "$(since "$t" | cut -d. -f1)" -lt "$HANG" ] || die "noVNC's page did not answer at $URL/vnc.html within $HANG s"
  sleep 0.2
done
figure "up: roscore healthy, the arm, robot_state_publisher and RViz started, noVNC answering in $(since "$t") s; the rviz service prints: $printed"
[ "$("${COMPOSE[@]}" ps -q arm)" = "$arm_id" ] && "${COMPOSE[@]}" logs arm 2>&1 | grep -q "snakekit ros: the sim arm is node" \
  || die "the arm's node, started 5 s before roscore, is not the one running: $("${COMPOSE[@]}" logs arm 2>&1 | tail -5)"
say "the arm's node, started 5 s before roscore, waited for it and runs (no restart)"
for s in roscore arm state-publisher rviz; do
  [ "$("${COMPOSE[@]}" ps -q "$s" | wc -l)" = 1 ] || die "the $s service is not running: $("${COMPOSE[@]}" logs "$s" 2>&1 | tail -5)"
done
ports=$($DOCKER ps --format '{{.Names}} {{.Ports}}' --filter "label=com.docker.compose.project=$PROJECT" | grep -v -- '-lab-' | grep -c -- '->' || true)
[ "$ports" = 1 ] || die "the ROS services publish $ports ports (one wanted: RViz's noVNC)"

# --- RViz in the browser, the arm at home ------------------------------------------------------
rm -rf "$SHOTS" && mkdir -p "$SHOTS"
t=$(now)
"$VENV_BIN/python" docker/ros/rviz-check "$URL" "$SHOTS/home.png" --hang "$HANG" || die "RViz in noVNC does not show the arm"
figure "RViz in noVNC in headless Chromium, the arm at home drawn, in $(since "$t") s"

# --- inside the stack: a small node sends goals and reads the joint states back --------------------
t=$(now)
"${COMPOSE[@]}" cp docker/ros/check-stack.py arm:/tmp/check-stack.py >/dev/null 2>&1 || die "could not copy the check into the arm's container"
"${COMPOSE[@]}" exec -T arm python /tmp/check-stack.py /home/student/work "$HANG" 2>&1 | tee "$RUN/check.log" | sed 's/^ros-check: /ros-test: /'
grep -q "the arm holds" "$RUN/check.log" || die "the check inside the stack failed"
figure "the node inside the stack: refusal, sweep, rosbag play and a pose in $(since "$t") s"

# --- RViz again: the arm in its new pose ----------------------------------------------------------
"$VENV_BIN/python" docker/ros/rviz-check "$URL" "$SHOTS/pose.png" --differ-from "$SHOTS/home.png" --hang "$HANG" \
  || die "RViz in noVNC does not show the arm moved"

# --- a terminal in the stack (exec arm bash): rostopic echo, rosbag record -----------------------
t=$(now)
out=$("${COMPOSE[@]}" exec -T arm bash -l -c "cd ~/work && rostopic echo -n 1 /joint_states/name \
  && timeout $HANG rosbag record -q -l 100 -O recorded.bag /joint_states /tf >/dev/null 2>&1 \
  && echo '=== rosbag info' && rosbag info -y -k topics recorded.bag" 2>&1) \
  || die "rostopic echo / rosbag record from a terminal in the arm's container failed: $out"
grep -q "joint5" <<<"$out" || die "rostopic echo /joint_states showed no joint5: $out"
# rosbag record -l 100: each topic's first 100 messages, then it stops
recorded=$(python3 -c '
import sys, yaml
topics = {t["topic"]: t["messages"] for t in yaml.safe_load(sys.stdin.read().split("=== rosbag info", 1)[1])}
assert topics == {"/joint_states": 100, "/tf": 100}, topics
print(", ".join(f"{k} {v}" for k, v in sorted(topics.items())))' <<<"$out") || die "rosbag record: $out"
# kept on the host as docs/ros.md says (exec -T arm cat), and read there by another reader (rosbags)
"${COMPOSE[@]}" exec -T arm cat recorded.bag > "$RUN/recorded.bag" || die "could not copy recorded.bag out as docs/ros.md says"
kept=$("$VENV_BIN/python" -c 'import sys
from rosbags.rosbag1 import Reader
with Reader(sys.argv[1]) as r: print(r.message_count)' "$RUN/recorded.bag") || die "recorded.bag, copied out, does not read"
[ "$kept" = 200 ] || die "recorded.bag, copied out, holds $kept messages (200 recorded)"
say "a terminal in the arm's container (exec arm bash): rostopic echo /joint_states names joint1..joint5; rosbag record -l 100: $recorded messages, copied out (exec -T arm cat) and read on the host ($(since "$t") s)"
# the sweep as docs/ros.md sends it from that terminal (rostopic pub), run to its end
t=$(now)
sed -n '/^rostopic pub -1 \/arm\/command trajectory_msgs\/JointTrajectory "\$(python/,/^```$/p' docs/ros.md | sed '$d' > "$RUN/pub.sh"
[ -s "$RUN/pub.sh" ] || die "docs/ros.md has no rostopic pub of the sweep"
# (from home, where the sweep starts: the arm's node started again, the rest of the stack running on)
"${COMPOSE[@]}" restart arm >/dev/null 2>&1 || die "could not restart the arm's service"
until "${COMPOSE[@]}" exec -T arm bash -l -c 'timeout 10 rostopic echo -n 1 /joint_states/name' >/dev/null 2>&1; do
  [ "$(since "$t" | cut -d. -f1)" -lt "$HANG" ] || die "the arm's node did not come back within $HANG s"
  sleep 1
done
"${COMPOSE[@]}" exec -T arm bash -l -c "$(cat "$RUN/pub.sh")" >"$RUN/pub.log" 2>&1 || die "docs/ros.md's rostopic pub failed: $(tail -5 "$RUN/pub.log")"
until "${COMPOSE[@]}" exec -T roscore bash -c 'grep -h "goal done: 100 points" ~/.ros/log/latest/rosout.log' >"$RUN/done.log" 2>&1; do
  [ "$(since "$t" | cut -d. -f1)" -lt "$HANG" ] || die "the sweep docs/ros.md sends was not done within $HANG s"
  sleep 1
done
say "docs/ros.md's rostopic pub of the sweep: the arm says $(grep -o 'goal done: [^]]*' "$RUN/done.log" | head -1) ($(since "$t") s)"

# --- down: nothing of the profile left ------------------------------------------------------------
t=$(now)
"${COMPOSE[@]}" down >"$RUN/down.log" 2>&1 || { cat "$RUN/down.log" >&2; die "docker compose down failed"; }
left=$($DOCKER ps -aq --filter "label=com.docker.compose.project=$PROJECT")
[ -z "$left" ] || die "containers left after down: $left"
left=$($DOCKER network ls -q --filter "label=com.docker.compose.project=$PROJECT")
[ -z "$left" ] || die "networks left after down: $left"
# the lab's work volume is the students' (kept on purpose, docker/README.md); the ROS services make none
left=$($DOCKER volume ls -q --filter "label=com.docker.compose.project=$PROJECT" | grep -v -x "${PROJECT}_work" || true)
anonymous=$($DOCKER volume ls -q --filter dangling=true | grep -v -x "${PROJECT}_work" || true)
[ -z "$left$anonymous" ] || die "volumes left after down: $left $anonymous"
"${COMPOSE[@]}" down --volumes >/dev/null 2>&1
say "down in $(since "$t") s: no container, network or volume of the ros profile left (the lab's work volume is kept, as always)"
figure "the whole ROS test: $(since "$t_all") s"
say "passed"
