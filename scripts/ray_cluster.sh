#!/usr/bin/env bash
# Two-node Ray cluster on one Linux host, the worker node in its own network namespace.
#
#   scripts/ray_cluster.sh up       create netns + veth (if missing), start head + worker node (token auth)
#   scripts/ray_cluster.sh status   show network, node processes and `ray status`
#   scripts/ray_cluster.sh down     stop only the nodes started by `up`, delete netns/veth and the state dir
#
# Layout (root required for `ip netns`):
#   root namespace   : veth rayh0 10.200.0.1/24  -> head node (--num-cpus 0, GCS on :6379); drivers run here
#   netns "raywrk"   : veth rayw0 10.200.0.2/24  -> worker node (--num-cpus 2)
#
# A driver in the root namespace needs:
#   export RAY_AUTH_MODE=token RAY_AUTH_TOKEN_PATH=/tmp/raycl/auth_token   (and RAY_AUTH_TOKEN unset)
#   ray.init(address="10.200.0.1:6379")
#
# Never uses `ray stop` (it kills every Ray process on the host, including other people's clusters):
# each node runs as `ray start --block` under `setsid` and is stopped with SIGTERM to that process (it drains
# and stops its children); then any process still in that session (or with RAYCL_TAG in its environment) is
# SIGKILLed. Leftovers only happen if the `ray start` process itself was killed hard: its agents outlive it.
#
# Settings (environment): RAYCL_DIR (/tmp/raycl), RAYCL_NS (raywrk), RAYCL_PORT (6379),
# RAYCL_WORKER_CPUS (2), RAYCL_OBJECT_STORE_BYTES (500000000), RAY_BIN (<repo>/.venv/bin/ray),
# RAYCL_DASHBOARD_PORT (8265: the dashboard, which serves `ray job submit`; 0 turns it off), RAYCL_AGENT_PORT (52375),
# RAYCL_KEEP_LOGS=1 keeps the state dir on `down`.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
RAY_BIN=${RAY_BIN:-$ROOT/.venv/bin/ray}
[[ -x $RAY_BIN ]] || RAY_BIN=$(command -v ray)
PY=$(dirname "$RAY_BIN")/python
[[ -x $PY ]] || PY=python3

STATE=${RAYCL_DIR:-/tmp/raycl}
NS=${RAYCL_NS:-raywrk}
VETH_H=rayh0
VETH_W=rayw0
HEAD_IP=10.200.0.1
WRK_IP=10.200.0.2
PREFIX=24
PORT=${RAYCL_PORT:-6379}
WORKER_CPUS=${RAYCL_WORKER_CPUS:-2}
OBJ_MEM=${RAYCL_OBJECT_STORE_BYTES:-500000000}
DASH_PORT=${RAYCL_DASHBOARD_PORT:-8265}
AGENT_PORT=${RAYCL_AGENT_PORT:-52375}
TOKEN=$STATE/auth_token
TAG="raycl:$STATE"          # put into every node's environment; used to find leftovers on `down`
ADDR=$HEAD_IP:$PORT

log() { printf '[ray_cluster] %s\n' "$*" >&2; }
die() { log "ERROR: $*"; exit 1; }

# Environment for every ray command of this cluster. RAY_AUTH_TOKEN would override RAY_AUTH_TOKEN_PATH,
# RAY_ADDRESS would redirect CLI/driver address resolution: drop both.
ray_env() {
  env -u RAY_AUTH_TOKEN -u RAY_ADDRESS RAY_AUTH_MODE=token RAY_AUTH_TOKEN_PATH="$TOKEN" \
      RAYCL_TAG="$TAG" RAY_USAGE_STATS_ENABLED=0 "$@"
}

ns_exists() { ip netns list | awk '{print $1}' | grep -qx "$NS"; }

pid_alive() {  # pidfile -> 0 if the recorded `ray start` process is alive
  local f=$1 p
  [[ -s $f ]] || return 1
  p=$(<"$f")
  [[ -r /proc/$p/cmdline ]] && tr '\0' ' ' <"/proc/$p/cmdline" | grep -q "ray start"
}

net_up() {
  ns_exists || { log "creating netns $NS"; ip netns add "$NS"; }
  if ! ip link show "$VETH_H" >/dev/null 2>&1; then
    # a stale peer left inside the namespace would block re-creation
    ip netns exec "$NS" ip link del "$VETH_W" 2>/dev/null || true
    log "creating veth $VETH_H <-> $VETH_W"
    ip link add "$VETH_H" type veth peer name "$VETH_W"
    ip link set "$VETH_W" netns "$NS"
  fi
  ip addr replace "$HEAD_IP/$PREFIX" dev "$VETH_H"
  ip link set "$VETH_H" up
  ip netns exec "$NS" ip addr replace "$WRK_IP/$PREFIX" dev "$VETH_W"
  ip netns exec "$NS" ip link set "$VETH_W" up
  ip netns exec "$NS" ip link set lo up
}

make_token() {
  mkdir -p "$STATE"; chmod 700 "$STATE"
  if [[ ! -s $TOKEN ]]; then
    (umask 077; "$PY" -c 'import secrets; print(secrets.token_hex(32), end="")' >"$TOKEN")
    log "new auth token in $TOKEN"
  fi
}

wait_port() {  # host port seconds
  local i
  for ((i = 0; i < $3; i++)); do
    (exec 3<>"/dev/tcp/$1/$2") 2>/dev/null && return 0
    sleep 1
  done
  return 1
}

start_head() {
  if pid_alive "$STATE/head.pid"; then log "head already running (pid $(<"$STATE/head.pid"))"; return; fi
  if wait_port "$HEAD_IP" "$PORT" 1; then die "$ADDR is already in use by something else"; fi
  log "starting head on $ADDR"
  local dash=(--include-dashboard=false)
  # the job server hands each job to the head's agent: its own port, not the 52365 any local Ray on this host takes
  [[ $DASH_PORT != 0 ]] && dash=(--include-dashboard=true --dashboard-host "$HEAD_IP" --dashboard-port "$DASH_PORT"
    --dashboard-agent-listen-port "$AGENT_PORT")
  ray_env setsid -f sh -c 'echo $$ >"$0/head.pid"; exec "$@" >"$0/head.log" 2>&1 </dev/null' "$STATE" \
    "$RAY_BIN" start --head --block --port "$PORT" --node-ip-address "$HEAD_IP" --num-cpus 0 \
    "${dash[@]}" --disable-usage-stats --temp-dir "$STATE/head" \
    --object-store-memory "$OBJ_MEM"
  wait_port "$HEAD_IP" "$PORT" 90 || { tail -20 "$STATE/head.log" >&2; die "head GCS did not come up"; }
  for _ in $(seq 60); do grep -q "Ray runtime started" "$STATE/head.log" && return; sleep 1; done
  tail -20 "$STATE/head.log" >&2; die "head did not finish starting"
}

start_worker() {
  if pid_alive "$STATE/wrk.pid"; then log "worker node already running (pid $(<"$STATE/wrk.pid"))"; return; fi
  log "starting worker node $WRK_IP in netns $NS ($WORKER_CPUS CPUs)"
  ray_env ip netns exec "$NS" setsid -f sh -c 'echo $$ >"$0/wrk.pid"; exec "$@" >"$0/wrk.log" 2>&1 </dev/null' "$STATE" \
    "$RAY_BIN" start --block --address "$ADDR" --node-ip-address "$WRK_IP" --num-cpus "$WORKER_CPUS" \
    --disable-usage-stats --temp-dir "$STATE/wrk" --object-store-memory "$OBJ_MEM"
  for _ in $(seq 90); do
    grep -q "Ray runtime started" "$STATE/wrk.log" 2>/dev/null && return
    [[ -s $STATE/wrk.pid ]] && ! pid_alive "$STATE/wrk.pid" && break
    sleep 1
  done
  tail -20 "$STATE/wrk.log" >&2; die "worker node did not start"
}

alive_nodes() {
  ray_env "$RAY_BIN" status --address "$ADDR" 2>/dev/null |
    awk '/^Active:/{a=1;next} /^Pending:/{a=0} a && /node_/{n++} END{print n+0}' || true
}

cmd_up() {
  [[ $EUID -eq 0 ]] || die "must run as root (ip netns)"
  make_token
  net_up
  start_head
  start_worker
  local n=0
  for _ in $(seq 60); do n=$(alive_nodes); [[ $n -ge 2 ]] && break; sleep 2; done
  [[ $n -ge 2 ]] || die "only $n node(s) alive after waiting"
  log "cluster up: $n nodes"
  cat <<EOF
RAY CLUSTER ADDRESS: $ADDR
$([[ $DASH_PORT != 0 ]] && echo "RAY JOBS ADDRESS: http://$HEAD_IP:$DASH_PORT   (ray job submit --address ...)")
# in the driver's shell (root network namespace):
export RAY_AUTH_MODE=token
export RAY_AUTH_TOKEN_PATH=$TOKEN
unset RAY_AUTH_TOKEN
# python: ray.init(address="$ADDR")   (or export RAY_ADDRESS=$ADDR; note it redirects every ray.init())
EOF
}

tagged_pids() {  # pids of this cluster: session id == a recorded `ray start` pid, or RAYCL_TAG in environ
  # (ray::* processes overwrite their environ via setproctitle, so the session id is the reliable key)
  local sids=() f p
  for f in "$STATE/head.pid" "$STATE/wrk.pid"; do [[ -s $f ]] && sids+=("$(<"$f")"); done
  if ((${#sids[@]})); then
    ps -e -o pid=,sid= | awk -v s=" ${sids[*]} " -v me="$$" '$1 != me && index(s, " " $2 " ") {print $1}'
  fi
  for p in /proc/[0-9]*; do
    p=${p#/proc/}
    [[ $p == "$$" || $p == "$BASHPID" ]] && continue
    grep -qzxF "RAYCL_TAG=$TAG" "/proc/$p/environ" 2>/dev/null && echo "$p"
  done
  return 0
}

kill_tagged() {  # SIGKILL leftovers of this cluster (see tagged_pids)
  local p victims=()
  for p in $(tagged_pids | sort -un); do
    log "killing leftover pid $p: $(tr '\0' ' ' 2>/dev/null <"/proc/$p/cmdline" | cut -c1-80)"
    kill -KILL "$p" 2>/dev/null || true
    victims+=("$p")
  done
  for p in "${victims[@]}"; do  # let init reap them
    for _ in $(seq 20); do [[ -d /proc/$p ]] || break; sleep 0.25; done
  done
  return 0
}

stop_node() {  # name
  local f=$STATE/$1.pid p
  pid_alive "$f" || return 0
  p=$(<"$f")
  log "stopping $1 node (SIGTERM to pid $p)"
  kill -TERM "$p" 2>/dev/null || true
  for _ in $(seq 45); do [[ -d /proc/$p ]] || return 0; sleep 1; done
  log "$1 node still alive after 45 s, SIGKILL"
  kill -KILL "$p" 2>/dev/null || true
}

cmd_down() {
  [[ $EUID -eq 0 ]] || die "must run as root (ip netns)"
  stop_node wrk
  stop_node head
  sleep 1
  kill_tagged
  if ns_exists; then log "deleting netns $NS"; ip netns del "$NS"; fi
  ip link show "$VETH_H" >/dev/null 2>&1 && ip link del "$VETH_H"
  if [[ ${RAYCL_KEEP_LOGS:-0} == 1 ]]; then
    rm -f "$STATE"/*.pid
  else
    rm -rf "$STATE"
  fi
  log "down"
}

cmd_status() {
  echo "netns:   $(ns_exists && echo "$NS present" || echo "$NS absent")"
  echo "veth:    $(ip -br addr show "$VETH_H" 2>/dev/null || echo "$VETH_H absent")"
  ns_exists && echo "netns:   $(ip netns exec "$NS" ip -br addr show "$VETH_W" 2>/dev/null)"
  local n
  for n in head wrk; do
    if pid_alive "$STATE/$n.pid"; then echo "$n:    running (pid $(<"$STATE/$n.pid"))"; else echo "$n:    not running"; fi
  done
  echo "procs:   $(tagged_pids | sort -un | wc -l) processes belong to this cluster (session id / RAYCL_TAG)"
  if pid_alive "$STATE/head.pid"; then
    echo "address: $ADDR   driver env: RAY_AUTH_MODE=token RAY_AUTH_TOKEN_PATH=$TOKEN"
    [[ $DASH_PORT != 0 ]] && echo "jobs:    http://$HEAD_IP:$DASH_PORT"
    ray_env "$RAY_BIN" status --address "$ADDR" 2>&1 | sed -n '/^Node status/,/^Pending:/p' | grep -v '^Pending:' || true
  fi
}

case ${1:-} in
  up) cmd_up ;;
  down) cmd_down ;;
  status) cmd_status ;;
  *) echo "usage: $0 up|down|status" >&2; exit 2 ;;
esac
