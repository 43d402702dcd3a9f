#!/usr/bin/env bash
# The container test: a real Docker engine (Debian's docker.io) builds snakekit's image on a
# base made here with debootstrap, then runs the compose services and checks what users meet.
#
#   docker/test.sh            (as root; tests/system/test_docker.py runs it within `make test`)
#
# Steps: install docker.io, debootstrap (apt) when missing; start dockerd with its own data
# root and socket; make debian:bookworm-slim with debootstrap + docker import (cached);
# hadolint the Dockerfile; validate compose.yaml with compose v2; build with the user's command
# (`docker compose -f docker/compose.yaml build lab`: the builder compose picks, the classic one
# on Debian's docker.io); run `lab` and check /lab with the token, the user, the health check,
# the work volume and the 3D viewer through the lab's port; open it in headless Chromium from the host
# (docker/browser-check: the lessons listed, lesson 0 run, the arm drawn and moving in the 3D
# view); build the grader's image (--target grader) and read every file of both images' layers:
# nothing of the instructor's course (course/source, course/cases, course/references, a solution
# line) in the students', all of it in the grader's (docker/check-no-course); execute a lesson
# inside (instructor and student versions); run `grader` with networking off on sample
# submissions and check its CSV, gradebook and feedback.
# Figures are printed on lines starting with "figure:".
#
# The engine, its start and stop and the host's restore are docker/engine.sh (shared with `make bench`).
# The engine runs without touching iptables, ip_forward or the default bridge
# (--iptables=false --ip-forward=false --bridge=none); the host's iptables/nftables rules,
# forwarding and bridge settings and its network links are recorded first and, on exit,
# compared and restored if anything changed. The daemon is always stopped.
#
# Cache: ${SNAKEKIT_CACHE:-~/.cache/snakekit}: the base tarball and the engine's data root
# (images and build cache), so a second run is warm. Delete it for a cold run.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
VENV_BIN="$ROOT/${SNAKEKIT_VENV:-.venv}/bin"
IMAGE=snakekit-lab:latest
PROJECT=snakekit-test

say() { echo "docker-test: $*"; }
figure() { echo "figure: $*"; }
die() { echo "docker-test: FAILED: $*" >&2; exit 1; }
# shellcheck source=docker/engine.sh
source "$ROOT/docker/engine.sh"

[ "$(id -u)" = 0 ] || die "needs root (apt-get, dockerd); run it as root, e.g. sudo docker/test.sh"
[ -x "$VENV_BIN/hadolint" ] && [ -x "$VENV_BIN/docker-compose" ] \
  || die "hadolint or docker-compose missing from $VENV_BIN; run 'make setup'"

engine_packages || die "could not install docker.io, debootstrap, curl"
COMPOSE=("$VENV_BIN/docker-compose" -p "$PROJECT" -f "$ROOT/docker/compose.yaml")

# --- one run at a time on this machine ---------------------------------------------------
engine_lock 1800

engine_on_stop() { "${COMPOSE[@]}" --profile grader --profile hardware --profile hardware-usb down --volumes --remove-orphans >/dev/null 2>&1; }
trap engine_exit EXIT
trap 'exit 130' INT TERM

# --- the engine and the base image -------------------------------------------------------
engine_start
cold=$ENGINE_COLD
engine_base

# --- lint and validate -------------------------------------------------------------------
"$VENV_BIN/hadolint" docker/Dockerfile || die "hadolint found problems in docker/Dockerfile"
say "hadolint: docker/Dockerfile is clean"
for profile in "" "--profile hardware" "--profile hardware-usb" "--profile grader"; do
  # shellcheck disable=SC2086
  "${COMPOSE[@]}" $profile config -q || die "compose.yaml is invalid ($profile)"
done
say "compose $("$VENV_BIN/docker-compose" version --short): compose.yaml is valid (lab, hardware, hardware-usb, grader)"

# --- no CA or secret material in the repository; the build needs none ---------------------
# (docker/hub/z2jh-4.4.0/ is the chart's schema as published: its descriptions show the PEM form
# with "..." in place of a key)
leaked=$(git -C "$ROOT" grep -l -I -e 'BEGIN [C]ERTIFICATE' -e '[P]RIVATE KEY-----' -- . ':!docker/hub/z2jh-*/values.schema.yaml' \
         2>/dev/null || true)
[ -z "$leaked" ] || die "certificate or key material in the repository: $leaked"
! grep -n -E -e '--mount|--secret|/run/secrets' docker/Dockerfile || die "docker/Dockerfile mounts secrets or caches"
say "repository: no certificates or keys; the Dockerfile mounts no secrets"

# --- build, as a user does: docker compose -f docker/compose.yaml build lab -----------------
t=$(now)
engine_build "$IMAGE" "$RUN/build.log" || { tail -40 "$RUN/build.log" >&2; die "docker compose build failed"; }
build_s=$(since "$t")
builder=classic; grep -q -E '^#[0-9]+ ' "$RUN/build.log" && builder=BuildKit
figure "build: $build_s s ($([ "$cold" = 1 ] && echo "cold: empty engine cache" || echo "warm: engine cache kept"); compose build lab, $builder builder)"
size=$($DOCKER image inspect -f '{{.Size}}' "$IMAGE")
figure "image: $(( size / 1000000 )) MB (target <= 800 MB, limit 1000 MB)"
$DOCKER history --format '{{.Size}}\t{{.CreatedBy}}' "$IMAGE" \
  | awk -F'\t' '$1 ~ /MB|GB/ { sub(/^.*(RUN|COPY) /, "", $2); printf "figure:   %8s  %s\n", $1, substr($2, 1, 70) }'
[ "$size" -le 1000000000 ] || die "the image is $(( size / 1000000 )) MB, above the 1000 MB limit"

# --- the grader's image; the students' image holds nothing of the instructor's course ----------
# (the grader's image, on the students' layers: compose's grader service, docker/hub/grade)
t=$(now)
"${COMPOSE[@]}" --profile grader build grader >"$RUN/build-grader.log" 2>&1 \
  || { tail -40 "$RUN/build-grader.log" >&2; die "docker compose build grader failed"; }
figure "build of the grader's image (compose build grader, --target grader): $(since "$t") s; $(( $($DOCKER image inspect -f '{{.Size}}' snakekit-grader:latest) / 1000000 )) MB"
# every file of every layer, as a student who pulls the image gets them; and the same check on
# the grader's image, which must find all of it (the check can fail)
$DOCKER save "$IMAGE" | "$VENV_BIN/python" docker/check-no-course >"$RUN/no-course.log" 2>&1 \
  || { cat "$RUN/no-course.log" >&2; die "the students' image holds files or solutions of the instructor's course"; }
sed 's/^/docker-test: students'"'"' image: /' "$RUN/no-course.log"
$DOCKER save snakekit-grader:latest | "$VENV_BIN/python" docker/check-no-course --expect-course >"$RUN/course.log" 2>&1 \
  || { cat "$RUN/course.log" >&2; die "the grader's image lacks the course, or the check cannot find it"; }
sed 's/^/docker-test: grader'"'"'s image: /' "$RUN/course.log"

# --- time from docker run to /lab answering -------------------------------------------------
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
http_code() { curl -s -o /dev/null -w '%{http_code}' --max-time 2 "$1" || true; }
TOKEN=$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')
# the engine has no default bridge (--bridge=none): a network of our own, as compose makes one
$DOCKER network create snakekit-test-run >/dev/null
times=()
for i in 1 2 3; do
  port=$(free_port)
  t=$(now)
  $DOCKER run -d --rm --name "snakekit-start-$i" --network snakekit-test-run --init -e JUPYTER_TOKEN="$TOKEN" -p "127.0.0.1:$port:8888" "$IMAGE" 2>&1 >/dev/null \
    | grep -v "IPv4 forwarding is disabled" >&2 || true  # host-to-container needs no forwarding
  until [ "$(http_code "http://127.0.0.1:$port/lab?token=$TOKEN")" = 200 ]; do
    [ "$(since "$t" | cut -d. -f1)" -lt 60 ] || die "/lab did not answer within 60 s: $($DOCKER logs "snakekit-start-$i" 2>&1 | tail -5)"
    sleep 0.05
  done
  times+=("$(since "$t")")
  $DOCKER rm -f "snakekit-start-$i" >/dev/null
done
$DOCKER network rm snakekit-test-run >/dev/null
median=$(printf '%s\n' "${times[@]}" | sort -n | sed -n 2p)
figure "docker run to /lab answering: median $median s of ${times[*]} (target <= 3 s)"

# --- the lab service ---------------------------------------------------------------------
export JUPYTER_TOKEN=$TOKEN SNAKEKIT_LAB_PORT
SNAKEKIT_LAB_PORT=$(free_port)
LAB="http://127.0.0.1:$SNAKEKIT_LAB_PORT"
t=$(now)
"${COMPOSE[@]}" up -d lab >"$RUN/compose.log" 2>&1 || { cat "$RUN/compose.log" >&2; die "compose up lab failed"; }
CID=$("${COMPOSE[@]}" ps -q lab)
until [ "$(http_code "$LAB/lab?token=$TOKEN")" = 200 ]; do
  [ "$(since "$t" | cut -d. -f1)" -lt 60 ] || die "lab: /lab did not answer within 60 s"
  sleep 0.05
done
curl -s --max-time 5 "$LAB/lab?token=$TOKEN" | grep "JupyterLab" >/dev/null || die "lab: /lab is not JupyterLab's page"
code=$(http_code "$LAB/api/contents")
[ "$code" = 403 ] || die "lab: the API answered $code without the token (expected 403)"
code=$(http_code "$LAB/api/contents?token=wrong$TOKEN")
[ "$code" = 403 ] || die "lab: the API answered $code to a wrong token (expected 403)"
# the lessons are in the work folder
want=$(cd notebooks && ls -- *.ipynb | sort | tr '\n' ' ')
got=$(curl -s --max-time 5 "$LAB/api/contents?token=$TOKEN" | python3 -c \
  'import json, sys; print(" ".join(sorted(c["name"] for c in json.load(sys.stdin)["content"] if c["type"] == "notebook")) + " ")')
[ "$got" = "$want" ] || die "lab: lessons served: '$got', expected '$want'"
say "lab: /lab answers with the token ($(since "$t") s after compose up), 403 without; lessons: $got"
# the URL with the token is printed
"${COMPOSE[@]}" logs lab 2>&1 | grep -F "http://localhost:$SNAKEKIT_LAB_PORT/lab?token=$TOKEN" >/dev/null \
  || die "lab: the log does not print the URL with the token"
# not root
uid=$($DOCKER exec "$CID" id -u)
[ "$uid" != 0 ] || die "lab: runs as root"
user=$($DOCKER top "$CID" -o pid,uid,args | awk '/jupyter-lab|jupyter lab/ {print $2; exit}')
[ -n "$user" ] && [ "$user" != 0 ] || die "lab: JupyterLab's process runs as '${user:-?}'"
say "lab: runs as uid $uid ($($DOCKER exec "$CID" id -un)); the JupyterLab process as uid $user"
# healthy
t=$(now)
until [ "$($DOCKER inspect -f '{{.State.Health.Status}}' "$CID")" = healthy ]; do
  [ "$(since "$t" | cut -d. -f1)" -lt 90 ] || die "lab: not healthy within 90 s: $($DOCKER inspect -f '{{json .State.Health}}' "$CID")"
  sleep 0.5
done
say "lab: healthy"
sleep 10
mem=$($DOCKER stats --no-stream --format '{{.MemUsage}}' "$CID" | cut -d/ -f1)
figure "lab container idle memory: $mem"
# a lesson's kernel: started, then its first cell's imports
kt=$($DOCKER exec "$CID" python -c "
import time
from jupyter_client.manager import start_new_kernel
t = time.monotonic()
km, kc = start_new_kernel(kernel_name='python3')
t1 = time.monotonic()
r = kc.execute_interactive('import numpy, matplotlib.pyplot, snakekit; robot = snakekit.make_robot(\"sim\")', timeout=120)
t2 = time.monotonic()
assert r['content']['status'] == 'ok', r['content']
kc.complete('numpy.zer', 9); c = kc.get_shell_msg(timeout=60)['content']  # tab completion
km.shutdown_kernel(now=True)
assert 'zeros' in c['matches'], c['matches']
print(f'{t1 - t:.1f} s to a ready kernel, {t2 - t1:.1f} s for the first cell (numpy, matplotlib, snakekit, the simulator)')") \
  || die "lab: a kernel did not start or import the kit"
figure "lesson kernel: $kt"

# the 3D viewer, as a script in the container makes it, is reachable from the host through the
# lab's port alone (jupyter-server-proxy, with the lab's token): its own port is not published
$DOCKER exec -d "$CID" python -c "
from snakekit.viewer import Viewer
import time
v = Viewer()
open('/tmp/viewer-url', 'w').write(v.url)
time.sleep(120)"
t=$(now)
until $DOCKER exec "$CID" test -s /tmp/viewer-url; do
  [ "$(since "$t" | cut -d. -f1)" -lt 60 ] || die "viewer: no viewer started within 60 s"
  sleep 0.2
done
vurl=$($DOCKER exec "$CID" cat /tmp/viewer-url)
vport=$(sed -nE 's#^http://localhost:([0-9]+)/static/$#\1#p' <<<"$vurl")
[ -n "$vport" ] || die "viewer: URL $vurl, expected http://localhost:<port>/static/ (a script's viewer: its own port)"
curl -s --max-time 5 -H "Authorization: token $TOKEN" "$LAB/proxy/$vport/static/" | grep -i "meshcat" >/dev/null \
  || die "viewer: the lab's port does not serve its page at $LAB/proxy/$vport/static/"
code=$(http_code "$LAB/proxy/$vport/static/")
[ "$code" != 200 ] || die "viewer: $LAB/proxy/$vport/static/ answered without the token"
! curl -s --max-time 2 "http://127.0.0.1:$vport/static/" 2>/dev/null | grep -qi "meshcat" \
  || die "viewer: its own port $vport answers on the host: it must not be published"
say "viewer: a 3D view served on the container's port $vport reaches the host at $LAB/proxy/$vport/static/ (with the token), not on its own port"

# the lab in a browser on the host: the lessons listed, lesson 0 run, the arm drawn and moving
t=$(now)
"$VENV_BIN/python" docker/browser-check "$LAB" "$ROOT/artifacts" --token "$TOKEN" >"$RUN/browser.log" 2>&1 \
  || { tail -30 "$RUN/browser.log" >&2; die "the lab in headless Chromium: see above (screenshots in artifacts/)"; }
sed 's/^/docker-test: /' "$RUN/browser.log"
figure "browser check of the lab (lessons listed, lesson 0 run, arm drawn and moved) in $(since "$t") s"

# what the student writes stays in the volume when the container goes
curl -s --max-time 5 -X PUT -H 'Content-Type: application/json' \
  -d '{"type": "file", "format": "text", "content": "my notes"}' "$LAB/api/contents/notes.txt?token=$TOKEN" >/dev/null
"${COMPOSE[@]}" down >/dev/null 2>&1
"${COMPOSE[@]}" up -d lab >/dev/null 2>&1
t=$(now)
until [ "$(http_code "$LAB/lab?token=$TOKEN")" = 200 ]; do
  [ "$(since "$t" | cut -d. -f1)" -lt 60 ] || die "lab: no answer after the restart"
  sleep 0.1
done
content=$(curl -s --max-time 5 "$LAB/api/contents/notes.txt?token=$TOKEN&content=1" \
  | python3 -c 'import json, sys; print(json.load(sys.stdin).get("content"))')
[ "$content" = "my notes" ] || die "lab: a file written before the container went is lost (got '$content')"
say "lab: the work volume keeps what the student wrote across down/up"
CID=$("${COMPOSE[@]}" ps -q lab)

# --- a lesson executed inside the container -------------------------------------------------
# The instructor version (course/source, with the solutions) runs through; the student version
# in the work folder stops only in its exercise cells (the stubs raise NotImplementedError),
# and everything else in it works (lesson 06's plots show the student's own sweep, so none
# come before the exercises are done).
LESSON=${SNAKEKIT_DOCKER_LESSON:-06_coded_sweep}
check_executed() {  # FILE MODE: MODE=solved (no errors) or student (errors only in exercise cells)
  python3 - "$1" "$2" <<'EOF'
import json, sys
nb, mode = json.load(open(sys.argv[1])), sys.argv[2]
code = [c for c in nb["cells"] if c["cell_type"] == "code"]
outs = [o for c in code for o in c.get("outputs", [])]
def exercise(c):
    meta = c.get("metadata", {}).get("nbgrader", {})
    return bool(meta.get("solution") or meta.get("grade"))
failed = [c for c in code if any(o.get("output_type") == "error" for o in c.get("outputs", []))]
if mode == "solved":
    assert not failed, f"cells failed: {[o.get('ename') for c in failed for o in c['outputs'] if o.get('output_type') == 'error']}"
else:
    assert failed, "no exercise cell failed: the student version holds no stubs?"
    outside = [c.get("metadata", {}).get("nbgrader", {}).get("grade_id") or c["source"][:60] for c in failed if not exercise(c)]
    assert not outside, f"cells outside the exercises failed: {outside}"
print(sum("image/png" in o.get("data", {}) for o in outs), len(failed))
EOF
}
t=$(now)
# (each in a folder of its own, as a student's lesson writes its files next to itself)
# (the instructor's version from the repository: the students' image holds none)
$DOCKER exec "$CID" mkdir -p /tmp/solved
$DOCKER cp "course/source/$LESSON/$LESSON.ipynb" "$CID:/tmp/solved/$LESSON.ipynb" >/dev/null
$DOCKER exec "$CID" bash -c "cd /tmp/solved && jupyter nbconvert --to notebook --execute --ExecutePreprocessor.timeout=300 \
  --output-dir /tmp/executed $LESSON.ipynb" >"$RUN/lesson.log" 2>&1 \
  || { tail -30 "$RUN/lesson.log" >&2; die "lesson $LESSON (instructor version) failed inside the container"; }
$DOCKER cp "$CID:/tmp/executed/$LESSON.ipynb" "$RUN/solved.ipynb"
out=$(check_executed "$RUN/solved.ipynb" solved) || die "lesson $LESSON (instructor version): cells failed"
pngs=${out% *}
[ "$pngs" -ge 1 ] || die "lesson $LESSON: no plot arrived as image/png"
figure "lesson $LESSON (instructor version) executed inside the container in $(since "$t") s, $pngs pictures (image/png)"
t=$(now)
$DOCKER exec "$CID" bash -c "mkdir -p /tmp/student && cp $LESSON.ipynb /tmp/student/ && cd /tmp/student \
  && jupyter nbconvert --to notebook --execute --allow-errors --ExecutePreprocessor.timeout=300 \
  --output-dir /tmp/executed-student $LESSON.ipynb" >"$RUN/lesson-student.log" 2>&1 \
  || { tail -30 "$RUN/lesson-student.log" >&2; die "lesson $LESSON (student version) could not be executed inside the container"; }
$DOCKER cp "$CID:/tmp/executed-student/$LESSON.ipynb" "$RUN/student.ipynb"
out=$(check_executed "$RUN/student.ipynb" student) || die "lesson $LESSON (student version): see above"
say "lesson $LESSON (student version, as handed out): only its ${out#* } exercise cells stop, ${out% *} pictures, in $(since "$t") s"
$DOCKER exec "$CID" python -c "import ipykernel, nbclient" || die "the image lacks ipykernel/nbclient"
$DOCKER exec "$CID" python -c "
import importlib.util as u, sys
test_only = [m for m in ('pytest', 'playwright', 'uv', 'hadolint') if u.find_spec(m)]
sys.exit(f'test-only packages in the image: {test_only}' if test_only else 0)" || die "test-only packages in the image"
say "image: ipykernel and nbclient inside; pytest, playwright, uv, hadolint not"
"${COMPOSE[@]}" down --volumes >/dev/null 2>&1

# --- the grader service, networking off ----------------------------------------------------
# Two students: alice hands in the lesson as handed out (the stubs: no points), bob the
# instructor's solution (every point). The grader runs each in its own sandbox.
ASSIGNMENT=${SNAKEKIT_ASSIGNMENT:-06_coded_sweep}
export SNAKEKIT_COURSE="$RUN/course" SNAKEKIT_ASSIGNMENT="$ASSIGNMENT"
mkdir -p "$SNAKEKIT_COURSE"/{submitted,gradebook,autograded,feedback}
for s in alice bob; do mkdir -p "$SNAKEKIT_COURSE/submitted/$s/$ASSIGNMENT"; done
cp "notebooks/$ASSIGNMENT.ipynb" "$SNAKEKIT_COURSE/submitted/alice/$ASSIGNMENT/"
cp "course/source/$ASSIGNMENT/$ASSIGNMENT.ipynb" "$SNAKEKIT_COURSE/submitted/bob/$ASSIGNMENT/"
chown -R 1000:1000 "$SNAKEKIT_COURSE"
t=$(now)
"${COMPOSE[@]}" run --rm grader >"$RUN/grader.log" 2>&1 || { tail -30 "$RUN/grader.log" >&2; die "the grader service failed"; }
grade_s=$(since "$t")
python3 - "$SNAKEKIT_COURSE" "$ASSIGNMENT" <<'EOF' || { tail -20 "$RUN/grader.log" >&2; die "the grader's results are wrong"; }
import csv, os, sys
course, assignment = sys.argv[1:]
rows = list(csv.DictReader(open(f"{course}/gradebook/grades.csv")))
assert rows and list(rows[0])[:9] == ["student", "assignment", "score", "max_score", "status", "raw_score",
                                      "late_penalty", "submitted_at", "detail"], rows[:1]
by = {r["student"]: r for r in rows}
assert set(by) == {"alice", "bob"}, by
exercises = list(rows[0])[9:]   # then one column per exercise: its points, which add up to the score
assert exercises and all(e.startswith("ex") and e.endswith("_test") for e in exercises), exercises
for r in rows:
    assert abs(sum(float(r[e]) for e in exercises) - float(r["raw_score"])) < 1e-6, r
for r in rows:
    assert r["assignment"] == assignment and r["status"] == "graded", r
    assert float(r["max_score"]) > 0, r
assert float(by["alice"]["score"]) == 0, by["alice"]
assert float(by["bob"]["score"]) == float(by["bob"]["max_score"]), by["bob"]
assert os.path.getsize(f"{course}/gradebook/gradebook.db") > 0, "no gradebook"
for s in ("alice", "bob"):
    assert os.listdir(f"{course}/feedback/{s}/{assignment}"), f"no feedback for {s}"
print(f"grader: alice {by['alice']['score']}/{by['alice']['max_score']}, bob {by['bob']['score']}/{by['bob']['max_score']}")
EOF
figure "grader: 2 submissions of $ASSIGNMENT graded with networking off, each in its sandbox, in $grade_s s"
say "passed"
