# The private Docker engine that docker/test.sh and bench/container-engine.sh share; source it.
#
# Debian's docker.io runs as a dockerd of our own: its own data root (the cache, so images
# and the build cache survive between runs), its own socket and exec root (a temporary folder),
# and it leaves iptables, ip_forward and the default bridge alone
# (--iptables=false --ip-forward=false --bridge=none). The host's iptables/nftables rules,
# forwarding and bridge settings, network links and the engine's mounts are recorded before the
# engine starts; engine_stop stops it, and restores and checks all of them.
#
# The caller sets ROOT (the repository), and defines say, figure and die; then:
#   engine_packages [PKG...]   install docker.io, debootstrap, curl (+PKG) when missing (apt; root)
#   engine_lock                one engine on this cache at a time (flock)
#   engine_start               record the host's state, start dockerd, export DOCKER_HOST, clear
#                              what a run stopped before its engine_stop left (engine_clear_left)
#   engine_base                debian:bookworm-slim, made with debootstrap + docker import (cached),
#                              with the host's CA bundle in it (this machine's TLS is re-signed)
#   engine_build IMAGE LOG     build the image as a user does: `docker compose -f docker/compose.yaml
#                              build lab` (compose v2 from the venv, VENV_BIN), tagged IMAGE
#   engine_stop                remove containers, stop dockerd, restore the host; returns 1 unless clean
#   engine_exit                the caller's EXIT trap: engine_stop, dockerd's log's end when anything
#                              failed, this run's folder removed; exits with the status (1 if not clean)
# and may define engine_on_stop (run first in engine_stop while the engine still answers).
# Variables: CACHE, DATA (data root), RUN (this run's temporary folder), DOCKER (the client),
# ENGINE_COLD (1 when the data root was empty), DOCKERD_PID.

CACHE=${SNAKEKIT_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/snakekit}
DATA="$CACHE/docker"
CA=${SNAKEKIT_CA_BUNDLE:-/etc/ssl/certs/ca-certificates.crt}
DOCKER=/usr/bin/docker   # Debian's client, whatever else is on PATH
RUN=""
DOCKERD_PID=""
ENGINE_COLD=0
# The builder is whichever compose picks, as for a user: Debian's docker.io has no buildx, so
# compose falls back to the classic builder (DOCKER_BUILDKIT=1 in the caller's environment
# makes it BuildKit; the Dockerfile builds with both).

now() { date +%s.%N; }
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }

# --- Debian's docker.io and debootstrap --------------------------------------------------
engine_packages() {
  local need_pkgs=() p policy_added=0
  for p in docker.io debootstrap curl "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || need_pkgs+=("$p")
  done
  [ ${#need_pkgs[@]} -gt 0 ] || return 0
  say "installing ${need_pkgs[*]}"
  # The package must not start a system-wide daemon: we run our own.
  if [ ! -e /usr/sbin/policy-rc.d ]; then
    printf '#!/bin/sh\nexit 101\n' > /usr/sbin/policy-rc.d && chmod +x /usr/sbin/policy-rc.d && policy_added=1
  fi
  DEBIAN_FRONTEND=noninteractive apt-get update -qq \
    && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need_pkgs[@]}" iptables >/dev/null
  local rc=$?
  [ "$policy_added" = 0 ] || rm -f /usr/sbin/policy-rc.d
  return $rc
}

# --- one engine at a time on this cache ----------------------------------------------------
engine_lock() {  # [WAIT_SECONDS]
  mkdir -p "$CACHE"
  exec 9>"$CACHE/docker-test.lock"
  flock -w "${1:-1800}" 9 || die "another run of the private engine holds $CACHE/docker-test.lock"
}

# --- the host's network state ----------------------------------------------------------------

# --- the host's network state, before ----------------------------------------------------
net_state() {  # rules and settings, without packet counters and timestamps
  { command -v iptables-save >/dev/null && { echo "## iptables"; iptables-save; echo "## ip6tables"; ip6tables-save; }
    command -v iptables-legacy-save >/dev/null && { echo "## legacy"; iptables-legacy-save; ip6tables-legacy-save; }
    command -v nft >/dev/null && { echo "## nft"; nft list ruleset; }
  } 2>/dev/null | grep -v '^#[^#]' | sed -E 's/\[[0-9]+:[0-9]+\]/[]/g' || true
}
SYSCTLS=(/proc/sys/net/ipv4/ip_forward /proc/sys/net/ipv6/conf/all/forwarding /proc/sys/net/ipv6/conf/default/forwarding
         /proc/sys/net/bridge/bridge-nf-call-iptables /proc/sys/net/bridge/bridge-nf-call-ip6tables
         /proc/sys/net/bridge/bridge-nf-call-arptables)
sysctl_state() { for f in "${SYSCTLS[@]}"; do [ -e "$f" ] && echo "$f $(cat "$f")"; done; true; }
link_state() { ip -o link show | awk -F': ' '{print $2}' | sed 's/@.*//' | sort; }
# mounts an engine makes (overlays, shm, netns, its data and exec roots); others' mounts vary
mount_state() { awk '{print $2}' /proc/mounts | grep -E "^($RUN|$DATA|/var/lib/docker|/run/docker|/run/containerd|/var/run/docker)" | sort || true; }
engine_record_host() {
  net_state > "$RUN/net.before"
  sysctl_state > "$RUN/sysctl.before"
  link_state > "$RUN/links.before"
  mount_state > "$RUN/mounts.before"
  command -v nft >/dev/null && nft list ruleset > "$RUN/nft.before" 2>/dev/null || true
  command -v iptables-save >/dev/null && iptables-save > "$RUN/iptables.before" 2>/dev/null || true
  command -v ip6tables-save >/dev/null && ip6tables-save > "$RUN/ip6tables.before" 2>/dev/null || true
}
engine_stop() {  # remove what ran, stop dockerd, restore the host; returns 1 unless the host is as before
  local restored=() foreign=() clean=1 ids pid l own=""
  if [ -n "$DOCKERD_PID" ] && kill -0 "$DOCKERD_PID" 2>/dev/null; then
    # this engine's links: its networks' bridges (br-<network id>) and what is attached to them
    own=$($DOCKER network ls -q --filter driver=bridge 2>/dev/null | while read -r n; do
      echo "br-$n"; ip -o link show master "br-$n" 2>/dev/null | awk -F': ' '{print $2}' | sed 's/@.*//'; done)
    declare -F engine_on_stop >/dev/null && engine_on_stop
    ids=$($DOCKER ps -aq 2>/dev/null); [ -z "$ids" ] || $DOCKER rm -f $ids >/dev/null 2>&1
    $DOCKER volume prune -f >/dev/null 2>&1
    $DOCKER network prune -f >/dev/null 2>&1
    # superseded builds; the classic builder's cache is untagged images (the venv stage's too),
    # so only those older than three days go
    $DOCKER image prune -f --filter until=72h >/dev/null 2>&1
    $DOCKER builder prune -f --keep-storage 4gb >/dev/null 2>&1  # the cache stays bounded
    kill -TERM "$DOCKERD_PID"
    for _ in $(seq 100); do kill -0 "$DOCKERD_PID" 2>/dev/null || break; sleep 0.2; done
    kill -0 "$DOCKERD_PID" 2>/dev/null && { say "dockerd did not stop in 20 s: killing it"; kill -KILL "$DOCKERD_PID"; }
  fi
  [ -n "$RUN" ] && [ -d "$RUN" ] || return 0
  # containerd and its shims were started for this run only (their paths name $RUN)
  for pid in $(grep -l -s -F "$RUN" /proc/[0-9]*/cmdline | cut -d/ -f3); do kill -KILL "$pid" 2>/dev/null; done
  grep -F -e "$RUN" -e "$DATA" /proc/mounts | awk '{print $2}' | sort -r | while read -r m; do umount -l "$m"; done
  [ -e "$RUN/net.before" ] || return 0  # the host was not recorded: nothing was started
  # the host's network state, after: restore whatever differs
  if ! diff -q <(sysctl_state) "$RUN/sysctl.before" >/dev/null; then
    while read -r f v; do [ "$(cat "$f")" = "$v" ] || { echo "$v" > "$f"; restored+=("$f=$v"); }; done < "$RUN/sysctl.before"
  fi
  # A link that appeared since the start is removed if it is this engine's, or if no other Docker
  # engine runs here (then nothing else made it); another engine's containers keep theirs.
  for l in $(comm -13 "$RUN/links.before" <(link_state)); do
    if grep -qx -F -- "$l" <<<"$own" || ! other_engine; then
      ip link delete "$l" 2>/dev/null && restored+=("link $l removed")
    else
      foreign+=("$l")
    fi
  done
  if ! diff -q <(net_state) "$RUN/net.before" >/dev/null; then
    if [ -s "$RUN/nft.before" ] || command -v nft >/dev/null; then
      nft flush ruleset && nft -f "$RUN/nft.before" && restored+=("nftables ruleset")
    else
      iptables-restore < "$RUN/iptables.before" && ip6tables-restore < "$RUN/ip6tables.before" && restored+=("iptables")
    fi
  fi
  [ ${#restored[@]} = 0 ] || say "restored on the host: ${restored[*]}"
  diff <(net_state) "$RUN/net.before" >&2 || { say "iptables/nftables differ from before"; clean=0; }
  diff <(sysctl_state) "$RUN/sysctl.before" >&2 || { say "forwarding/bridge settings differ from before"; clean=0; }
  if other_engine; then  # its links come and go: only this engine's must be gone
    l=$(comm -13 "$RUN/links.before" <(link_state) | grep -x -F -f <(printf '%s\n' "$own") || true)
    [ -z "$l" ] || { say "this engine's network links are still there: $l"; clean=0; }
    [ ${#foreign[@]} = 0 ] || say "another Docker engine runs here: its new links left alone (${foreign[*]})"
  else
    diff <(link_state) "$RUN/links.before" >&2 || { say "network links differ from before"; clean=0; }
  fi
  diff <(mount_state) "$RUN/mounts.before" >&2 || { say "the engine's mounts are still there"; clean=0; }
  pgrep -f -- "--data-root $DATA" >/dev/null && { say "a dockerd on $DATA still runs"; clean=0; }
  if [ "$clean" = 1 ]; then
    say "host state checked: iptables/nftables, ip_forward, bridge settings, links and mounts as before; no dockerd left"
    return 0
  fi
  return 1
}

engine_exit() {
  local rc=$?
  set +e
  engine_stop || rc=1
  [ "$rc" = 0 ] || [ -z "$RUN" ] || { echo "--- dockerd log (last 30 lines)" >&2; tail -30 "$RUN/dockerd.log" >&2; }
  [ -z "$RUN" ] || rm -rf "$RUN"
  exit "$rc"
}

other_engine() { pgrep -f -- '^dockerd ' >/dev/null; }  # after ours has stopped: another one

# --- the engine ----------------------------------------------------------------------------
engine_start() {
  local t
  RUN=$(mktemp -d /tmp/snakekit-docker.XXXXXX)
  export DOCKER_HOST="unix://$RUN/docker.sock"
  engine_record_host
  mkdir -p "$DATA"
  ENGINE_COLD=1
  [ -d "$DATA/image" ] && ENGINE_COLD=0
  engine_stop_stale
  # in a session of its own: a signal to the caller's process group (a test's time limit) stops the
  # script, whose engine_stop then removes what ran before it stops dockerd. Without the lock's fd
  # (9): a dockerd left by a killed run must not hold the lock for the next one.
  setsid dockerd --data-root "$DATA" --exec-root "$RUN/exec" --pidfile "$RUN/dockerd.pid" \
    --host "$DOCKER_HOST" --iptables=false --ip6tables=false --ip-forward=false --bridge=none \
    --default-address-pool base=10.213.0.0/16,size=24 >"$RUN/dockerd.log" 2>&1 9>&- &
  DOCKERD_PID=$!
  t=$(now)
  until $DOCKER version >/dev/null 2>&1; do
    kill -0 "$DOCKERD_PID" 2>/dev/null || die "dockerd exited: $(tail -5 "$RUN/dockerd.log")"
    [ "$(since "$t" | cut -d. -f1)" -lt 60 ] || die "dockerd did not answer within 60 s"
    sleep 0.2
  done
  ENGINE_START_S=$(since "$t")
  engine_clear_left
  say "dockerd $($DOCKER version -f '{{.Server.Version}}') up in $ENGINE_START_S s (data root $DATA)"
}

# A dockerd on this data root that a killed run left (SIGKILL skips engine_stop): we hold the lock,
# so it is no other run's. Stopped (SIGTERM, then SIGKILL after 30 s) before ours starts.
engine_stop_stale() {
  local pid n=0
  for pid in $(pgrep -f -- "^dockerd --data-root $DATA " || true); do
    say "a dockerd a killed run left on $DATA (pid $pid): stopped"
    kill "$pid" 2>/dev/null || true
    while kill -0 "$pid" 2>/dev/null && [ $n -lt 150 ]; do sleep 0.2; n=$((n + 1)); done
    kill -9 "$pid" 2>/dev/null || true
  done
}

# What a run stopped before its engine_stop (killed, machine restarted) left in the data root:
# the caller's services and swarm (engine_on_stop), containers and every volume. The data root
# is this engine's alone, so no volume in it is anyone else's: a student's home volume from a
# killed hub test would otherwise be the next run's, with its submissions in it.
engine_clear_left() {
  local ids
  declare -F engine_on_stop >/dev/null && engine_on_stop
  ids=$($DOCKER ps -aq 2>/dev/null); [ -z "$ids" ] || $DOCKER rm -f $ids >/dev/null 2>&1
  ids=$($DOCKER volume ls -q 2>/dev/null)
  [ -z "$ids" ] || { say "volumes a stopped run left, removed: $(echo $ids | wc -w)"; $DOCKER volume rm -f $ids >/dev/null 2>&1; }
  [ -z "$($DOCKER volume ls -q 2>/dev/null)" ] || die "volumes left in $DATA could not be removed: $($DOCKER volume ls -q | head -5 | tr '\n' ' ')"
}

# --- the base image: debian:bookworm-slim, made here ---------------------------------------
# The debootstrap tarball is cached as made (no CA in it). At import, the host's CA bundle
# ($CA) is added to the base as /usr/local/share/ca-certificates/host-ca-bundle.crt and
# /etc/ssl/certs/ca-certificates.crt, with SSL_CERT_FILE and PIP_CERT pointing at it: this
# machine reaches PyPI only through a proxy that re-signs TLS, and the build's downloads must
# trust it. The bundle comes from the host at the time the base is made; it is never in the
# repository. A label holds the bundle's hash: a changed bundle makes the base again.
engine_base() {
  local t rootfs ca_sum have tar_ca
  BASE_TAR="$CACHE/debian-bookworm-slim.tar"
  ca_sum=none
  [ -s "$CA" ] && ca_sum=$(sha256sum < "$CA" | cut -c1-64)
  have=$($DOCKER image inspect -f '{{index .Config.Labels "org.snakekit.host-ca"}}' debian:bookworm-slim 2>/dev/null || true)
  if [ "$have" != "$ca_sum" ]; then
    if [ ! -s "$BASE_TAR" ]; then
      t=$(now)
      rootfs="$RUN/rootfs"
      debootstrap --variant=minbase bookworm "$rootfs" http://deb.debian.org/debian >"$RUN/debootstrap.log" 2>&1 \
        || die "debootstrap failed: $(tail -3 "$RUN/debootstrap.log")"
      # slim, as Debian's own bookworm-slim: no docs, manuals, translations, apt caches or lists
      printf '%s\n' 'path-exclude=/usr/share/doc/*' 'path-include=/usr/share/doc/*/copyright' \
        'path-exclude=/usr/share/man/*' 'path-exclude=/usr/share/groff/*' 'path-exclude=/usr/share/info/*' \
        'path-exclude=/usr/share/locale/*' 'path-include=/usr/share/locale/locale.alias' \
        'path-exclude=/usr/share/lintian/*' 'path-exclude=/usr/share/linda/*' > "$rootfs/etc/dpkg/dpkg.cfg.d/docker"
      printf '%s\n' 'DPkg::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/*.bin || true"; };' \
        'APT::Update::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/*.bin || true"; };' \
        'Dir::Cache::pkgcache ""; Dir::Cache::srcpkgcache "";' > "$rootfs/etc/apt/apt.conf.d/docker-clean"
      echo 'Acquire::Languages "none";' > "$rootfs/etc/apt/apt.conf.d/docker-no-languages"
      find "$rootfs/usr/share/doc" -mindepth 1 -not -name copyright -not -type d -delete
      rm -rf "$rootfs"/usr/share/{man,groff,info,lintian,linda}/* "$rootfs"/var/cache/apt/*.bin \
        "$rootfs"/var/cache/apt/archives/*.deb "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/log/*.log
      find "$rootfs/usr/share/locale" -mindepth 1 -maxdepth 1 -not -name locale.alias -exec rm -rf {} +
      tar -C "$rootfs" --numeric-owner -cf "$BASE_TAR.part" . && mv "$BASE_TAR.part" "$BASE_TAR"
      rm -rf "$rootfs"
      figure "base: debootstrap --variant=minbase bookworm in $(since "$t") s"
    fi
    $DOCKER image rm -f debian:bookworm-slim >/dev/null 2>&1 || true
    if [ "$ca_sum" = none ]; then
      $DOCKER import -c 'CMD ["bash"]' -c 'LABEL org.snakekit.host-ca=none' "$BASE_TAR" debian:bookworm-slim >/dev/null
    else
      # the cached tarball plus the bundle, in this run's folder only
      tar_ca="$RUN/base-with-ca.tar"
      mkdir -p "$RUN/ca/usr/local/share/ca-certificates" "$RUN/ca/etc/ssl/certs"
      cp "$CA" "$RUN/ca/usr/local/share/ca-certificates/host-ca-bundle.crt"
      cp "$CA" "$RUN/ca/etc/ssl/certs/ca-certificates.crt"
      cp "$BASE_TAR" "$tar_ca"
      tar -C "$RUN/ca" --numeric-owner --owner=0 --group=0 -rf "$tar_ca" ./usr/local/share/ca-certificates/host-ca-bundle.crt ./etc/ssl/certs/ca-certificates.crt
      $DOCKER import -c 'CMD ["bash"]' -c "LABEL org.snakekit.host-ca=$ca_sum" \
        -c 'ENV SSL_CERT_FILE=/etc/ssl/certs/ca-certificates.crt PIP_CERT=/etc/ssl/certs/ca-certificates.crt' \
        "$tar_ca" debian:bookworm-slim >/dev/null
      rm -rf "$tar_ca" "$RUN/ca"
      say "base: the host's CA bundle ($CA) added to debian:bookworm-slim"
    fi
  fi
  figure "base: debian:bookworm-slim $(( $($DOCKER image inspect -f '{{.Size}}' debian:bookworm-slim) / 1000000 )) MB"
}

# --- the image -------------------------------------------------------------------------------
engine_build() {  # IMAGE LOG: the user's `docker compose -f docker/compose.yaml build lab`, tagged IMAGE
  (cd "$ROOT" && "$VENV_BIN/docker-compose" -f docker/compose.yaml build lab) >"$2" 2>&1 || return 1
  [ "$1" = snakekit-lab:latest ] || $DOCKER tag snakekit-lab:latest "$1"
}
