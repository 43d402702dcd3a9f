#!/usr/bin/env bash
# The ROS test: compose's `ros` profile (the study's multi-container set-up on our arm) on the
# private engine of docker/engine.sh, checked as a user meets it.
#
#   docker/ros/test.sh            (as root; tests/system/test_ros_compose.py runs it within `make test`)
#
# Steps: the engine (its own data root, the same cache as docker/test.sh, so the layers that test
# built are reused); the base; docker/ros/Dockerfile up to date (docker/ros/make-dockerfile --check)
# and hadolint-clean; compose.yaml valid with the profile; the tags snakekit-lab and snakekit-ros
# removed (their layers stay in the cache), so the first `up` meets an engine without either image
# as a new student's does and must build the ROS image without the students' (a cold engine runs
# the same steps, uncached); the arm's service started alone first (it builds the image; it waits
# for roscore); then `docker compose --profile ros up rviz` as docs/ros.md gives it, attached: the
# lab not started, rviz's log the only one shown and its last line the URL; the ROS image's size,
# the students' image built after it (`build lab`: the same layers, from the cache); RViz in noVNC
# in headless Chromium with the arm at home (docker/ros/rviz-check:
# the arm drawn); then, inside the stack, a small node in the arm's container
# (docker/ros/check-stack.py): a folding goal refused on /rosout with nothing moving, the Task 2
# sweep (shortened) followed by /joint_states as the kit's own simulator runs it, `rosbag play`
# of a kit .bag publishing its joint states, and the arm left in another pose; RViz screenshotted
# again (the arm drawn, its links elsewhere); `rostopic echo` and `rosbag record` from a terminal
# (`exec arm bash`), the bag copied out as docs/ros.md says; docs/ros.md's `rostopic pub` of the
# sweep, run to its end; its `rosnode list` and its record-and-play block (`rosbag record` stopped
# by Ctrl-C, `rosbag info`, `snakekit sweep --out`, `rosbag play`), each line as written; `down`: no
# container, network or volume left of the profile. On exit the
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
UP_PID=""
engine_on_stop() {
  "${COMPOSE[@]}" down --volumes --remove-orphans >/dev/null 2>&1
  [ -z "$UP_PID" ] || kill "$UP_PID" 2>/dev/null || true
}
trap engine_exit EXIT
trap 'exit 130' INT TERM
t_all=$(now)
engine_start
engine_base

# --- lint, validate ----------------------------------------------------------------------------
"$VENV_BIN/python" docker/ros/make-dockerfile --check || die "docker/ros/Dockerfile is out of date"
"$VENV_BIN/hadolint" docker/ros/Dockerfile || die "hadolint found problems in docker/ros/Dockerfile"
"${COMPOSE[@]}" config -q || die "compose.yaml is invalid with the ros profile"
services=$("${COMPOSE[@]}" config --services | sort | tr '\n' ' ')
[ "$services" = "arm lab roscore rviz state-publisher " ] || die "the ros profile's services: $services"
say "docker/ros/Dockerfile is up to date and hadolint-clean; compose.yaml is valid with the ros profile ($services)"
# a new student's engine has neither image: the ROS image's build must not need the students'
# (--no-prune: their parent layers stay, the classic builder's cache, so a cached run stays short)
for image in snakekit-ros:latest snakekit-lab:latest; do
  ! $DOCKER image inspect "$image" >/dev/null 2>&1 || $DOCKER image rm --no-prune "$image" >/dev/null || die "could not untag $image"
done

# --- up, as docs/ros.md gives it ----------------------------------------------------------------
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
export SNAKEKIT_ROS_PORT
SNAKEKIT_ROS_PORT=$(free_port)
URL="http://127.0.0.1:$SNAKEKIT_ROS_PORT"
# the arm first, without the master (--no-deps): it builds the ROS image, and must wait for roscore, not die
t=$(now)
"${COMPOSE[@]}" up -d --no-deps arm >"$RUN/up-arm.log" 2>&1 || { tail -40 "$RUN/up-arm.log" >&2; die "the first up (the arm's service) failed"; }
steps=$(grep -c '^Step ' "$RUN/up-arm.log" || true)
cached=$(grep -c 'Using cache' "$RUN/up-arm.log" || true)
figure "build: the ROS image by the first up, on an engine without the students' image, $(since "$t") s ($cached of $steps steps from the engine's cache; $([ "$ENGINE_COLD" = 1 ] && echo "cold: empty engine cache" || echo "engine cache kept"))"
arm_id=$("${COMPOSE[@]}" ps -q arm)
sleep 5
[ "$($DOCKER inspect -f '{{.State.Running}} {{.RestartCount}}' "$arm_id")" = "true 0" ] \
  || die "the arm's node, started before roscore, did not wait for it: $("${COMPOSE[@]}" logs arm 2>&1 | tail -5)"
# docs/ros.md's command, attached as a student runs it (it ends when the stack is taken down)
t=$(now)
"${COMPOSE[@]}" up rviz >"$RUN/up.log" 2>&1 </dev/null &
UP_PID=$!
printed=""
until printed=$(grep -o "open http://[^ ]*" "$RUN/up.log" | head -1) && [ -n "$printed" ]; do
  kill -0 "$UP_PID" 2>/dev/null || die "docker compose --profile ros up rviz ended: $(tail -5 "$RUN/up.log")"
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
[ -z "$("${COMPOSE[@]}" ps -q lab)" ] || die "up rviz started the lab too"
ports=$($DOCKER ps --format '{{.Names}} {{.Ports}}' --filter "label=com.docker.compose.project=$PROJECT" | grep -c -- '->' || true)
[ "$ports" = 1 ] || die "the ROS services publish $ports ports (one wanted: RViz's noVNC)"
# what the student reads: compose's own lines, then rviz's log alone, whose last line is the URL
shown=$(grep -c -- ' | ' "$RUN/up.log" || true)
[ "$(grep -- ' | ' "$RUN/up.log" | grep -v -c '^rviz-1 ' || true)" = 0 ] || die "up rviz shows other services' logs: $(grep -- ' | ' "$RUN/up.log" | grep -v '^rviz-1 ' | head -3)"
[ "$(tail -1 "$RUN/up.log")" = "rviz-1  | RViz in your browser: $printed" ] \
  || die "the URL is not the last line up rviz shows; it ends: $(tail -3 "$RUN/up.log")"
say "up rviz (docs/ros.md): the lab not started; the only service log shown is rviz's ($shown line), the URL its last line"

# the students' image, built after the ROS image: the same layers, from the engine's cache
t=$(now)
engine_build snakekit-lab:latest "$RUN/build-lab.log" || { tail -30 "$RUN/build-lab.log" >&2; die "docker compose build lab failed"; }
lab_steps=$(grep -c '^Step ' "$RUN/build-lab.log" || true)
lab_cached=$(grep -c 'Using cache' "$RUN/build-lab.log" || true)
figure "build: the students' image after it, $(since "$t") s ($lab_cached of $lab_steps steps from the engine's cache)"
ros_size=$($DOCKER image inspect -f '{{.Size}}' snakekit-ros:latest)
lab_size=$($DOCKER image inspect -f '{{.Size}}' snakekit-lab:latest)
# the ROS image is the students' plus its own layers (the kit and its venv shared, not copied)
lab_layers=$($DOCKER image inspect -f '{{join .RootFS.Layers " "}}' snakekit-lab:latest)
ros_layers=$($DOCKER image inspect -f '{{join .RootFS.Layers " "}}' snakekit-ros:latest)
[ "${ros_layers#"$lab_layers"}" != "$ros_layers" ] || die "the ROS image is not built on the students' image's layers"
gb() { awk -v b="$1" 'BEGIN { printf "%.2f", b / 1e9 }'; }
figure "ROS image $(gb "$ros_size") GB (snakekit-lab $(gb "$lab_size") GB; $(( (ros_size - lab_size) / 1000000 )) MB added: Debian's ROS 1, RViz, Xvfb, x11vnc, noVNC) (target <= 1.5 GB)"
[ "$ros_size" -le 1500000000 ] || die "the ROS image is $(gb "$ros_size") GB, above the 1.5 GB target"

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

# docs/ros.md's record-and-play block, each line as written: rosbag record stopped by Ctrl-C (SIGINT
# to its process group, as a terminal sends it), rosbag info, snakekit sweep --out, rosbag play (its
# /joint_states beside the arm's, as the page says: rostopic info lists both; stopped by Ctrl-C)
t=$(now)
sed -n '/^rosbag record -O sweep-recorded.bag/,/^```$/p' docs/ros.md | sed '$d' | sed 's/ *#.*$//' > "$RUN/block.sh"
mapfile -t block < "$RUN/block.sh"
[ "${#block[@]}" = 4 ] && [[ ${block[0]} == "rosbag record "* ]] && [[ ${block[1]} == "rosbag info "* ]] \
  && [[ ${block[2]} == "snakekit sweep "* ]] && [[ ${block[3]} == "rosbag play "* ]] \
  || die "docs/ros.md's record-and-play block is not record, info, sweep, play: $(cat "$RUN/block.sh")"
out=$("${COMPOSE[@]}" exec -T arm bash -l -c "cd ~/work
rosnode list
timeout -s INT 4 ${block[0]} >record.log 2>&1; echo \"record ended: \$?\"
${block[1]} && ${block[2]} >sweep.log 2>&1 && echo 'sweep written'
(sleep 4; rostopic info /joint_states >info.log 2>&1) &
timeout -s INT 8 ${block[3]} >play.log 2>&1; echo \"play ended: \$?\"
wait; cat info.log" 2>&1) || die "docs/ros.md's record-and-play block failed: $out"
# (and the page's rosnode list: the four nodes of the stack)
for node in /robot_state_publisher /rosout /snakekit_arm; do grep -q -x "$node" <<<"$out" || die "rosnode list lacks $node: $out"; done
grep -q "^/rviz_" <<<"$out" || die "rosnode list lacks RViz's node: $out"
grep -q "^record ended: 124$" <<<"$out" || die "rosbag record, stopped by Ctrl-C: $out"
info_js=$(grep -oE '/joint_states +[0-9]+ msgs' <<<"$out" | awk '{print $2}' || true)
info_tf=$(grep -oE '/tf +[0-9]+ msgs' <<<"$out" | awk '{print $2}' || true)
[ "${info_js:-0}" -gt 0 ] && [ "${info_tf:-0}" -gt 0 ] || die "rosbag info of sweep-recorded.bag lists no /joint_states and /tf messages: $out"
grep -q "^sweep written$" <<<"$out" || die "snakekit sweep --out kit-sweep.bag failed: $out"
publishers=$(sed -n '/^Publishers:/,/^$/p' <<<"$out" | grep -c '^ \* ' || true)
[ "$publishers" = 2 ] && grep -q '^ \* /snakekit_arm ' <<<"$out" && grep -q '^ \* /play_' <<<"$out" \
  || die "while kit-sweep.bag plays, rostopic info /joint_states does not list the arm and rosbag play: $out"
grep -q "^play ended: 124$" <<<"$out" || die "rosbag play, stopped by Ctrl-C: $out"
say "docs/ros.md's rosnode list (the four nodes) and its record-and-play block as written: rosbag record (Ctrl-C after 4 s) kept /joint_states $info_js, /tf $info_tf messages (rosbag info); snakekit sweep --out kit-sweep.bag; rosbag play of it published beside the arm (rostopic info /joint_states: 2 publishers) ($(since "$t") s)"

# --- down: nothing of the profile left ------------------------------------------------------------
t=$(now)
"${COMPOSE[@]}" down >"$RUN/down.log" 2>&1 || { cat "$RUN/down.log" >&2; die "docker compose down failed"; }
left=$($DOCKER ps -aq --filter "label=com.docker.compose.project=$PROJECT")
[ -z "$left" ] || die "containers left after down: $left"
left=$($DOCKER network ls -q --filter "label=com.docker.compose.project=$PROJECT")
[ -z "$left" ] || die "networks left after down: $left"
# the ROS services make no volume (the lab, which makes the work volume, was not started)
left=$($DOCKER volume ls -q --filter "label=com.docker.compose.project=$PROJECT")
anonymous=$($DOCKER volume ls -q --filter dangling=true)
[ -z "$left$anonymous" ] || die "volumes left after down: $left $anonymous"
wait "$UP_PID" 2>/dev/null || true  # up rviz ends with the stack
UP_PID=""
say "down in $(since "$t") s: no container, network or volume of the ros profile left"
figure "the whole ROS test: $(since "$t_all") s"
say "passed"
