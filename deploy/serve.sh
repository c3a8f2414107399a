#!/usr/bin/env bash
# Start the siteline service: the Prefect server (UI on http://127.0.0.1:4200), the siteline deployments,
# their concurrency limits and crash-recovery automations (deploy/service.py), a worker, the read-only
# preview server the UI loads images from, with the release browser and 3D viewer (http://127.0.0.1:4201),
# the reporter that writes on a crashed run's page why it stopped (deploy/reporter.py), and the upload
# watcher. The worker, the preview server, the reporter and the watcher are restarted when they die. Stop everything with Ctrl-C.
#
#   SITELINE_HOME       catalog and stores (default ./serve-home)
#   SITELINE_WATCH_DIR  folder to drop mission uploads into (default $SITELINE_HOME/uploads)
#   SITELINE_SITE       site the uploads belong to (default demo; created from the synthetic fence if missing,
#                       with auto release settings: change them with `siteline site update`)
#   SITELINE_RELEASE_POLICY  every-pair (default here) or on-demand
#   SITELINE_STORE_URL  data stores: a folder or an fsspec URL such as s3://bucket/siteline (default $SITELINE_HOME/stores)
#   SITELINE_PAIR_SLOTS pairs processed at once across all runs (default 2; each gets cores / slots threads)
#   PREFECT_PORT, SITELINE_PREVIEW_URL  the UI's port (4200) and where previews are served (http://127.0.0.1:4201)
#   SITELINE_STABLE_SECONDS  an upload without the marker is complete after this long unchanged (10)
#   PostgreSQL instead of SQLite, for both: deploy/postgres.env (see docs in it).
#   Workers on several machines (PostgreSQL, an object store, Dask): deploy/shared.env.
set -euo pipefail
cd "$(dirname "$0")/.."
export SITELINE_REPO="$PWD"
export SITELINE_HOME="${SITELINE_HOME:-$PWD/serve-home}"
export SITELINE_WATCH_DIR="${SITELINE_WATCH_DIR:-$SITELINE_HOME/uploads}"
export SITELINE_SITE="${SITELINE_SITE:-demo}"
export SITELINE_RELEASE_POLICY="${SITELINE_RELEASE_POLICY:-every-pair}"
export SITELINE_PREVIEW_URL="${SITELINE_PREVIEW_URL:-http://127.0.0.1:4201}"
PREFECT_PORT="${PREFECT_PORT:-4200}"
export PREFECT_HOME="${PREFECT_HOME:-$SITELINE_HOME/prefect}"
export PREFECT_API_URL="${PREFECT_API_URL:-http://127.0.0.1:$PREFECT_PORT/api}"
export PREFECT_UI_API_URL="$PREFECT_API_URL"
export PREFECT_SERVER_ANALYTICS_ENABLED=false
# the library's log lines reach the run logs; heartbeats let a dead run be detected (deploy/service.py:
# no heartbeat for 50 s marks it crashed: Prefect allows 30 s at least) and deploy/reporter.py says so on its page
export PREFECT_LOGGING_EXTRA_LOGGERS=siteline
export PREFECT_FLOWS_HEARTBEAT_FREQUENCY=30
# pairs processed at once across all runs (a Prefect concurrency limit), and the threads each may use:
# torch and numpy threads of every pair together must not exceed the cores (oversubscribed, each pair
# runs several times slower)
export SITELINE_PAIR_SLOTS="${SITELINE_PAIR_SLOTS:-2}"
threads=$(( $(nproc) / SITELINE_PAIR_SLOTS )); (( threads >= 1 )) || threads=1
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-$threads}" MKL_NUM_THREADS="${MKL_NUM_THREADS:-$threads}"
BIN="$PWD/.venv/bin"
LOGS="$SITELINE_HOME/logs"
mkdir -p "$SITELINE_HOME" "$SITELINE_WATCH_DIR" "$PREFECT_HOME" "$LOGS"

# on exit: TERM to every process of this group (server, supervisors, worker, flow runs), KILL 3 s later
cleanup() {
  trap - EXIT
  trap '' INT TERM  # this script outlives its own TERM to send the KILL
  local group; group=$(ps -o pgid= $$ | tr -d ' ')
  kill -TERM -- "-$group" 2>/dev/null || true
  sleep 3
  kill -KILL -- "-$group" 2>/dev/null || true
}
trap cleanup EXIT INT TERM

# keep <name> running: restart it (after 2 s) whenever it exits, logging to $LOGS/<name>.log
supervise() {
  local name="$1"; shift
  ( while true; do
      "$@" >>"$LOGS/$name.log" 2>&1 || true
      echo "$(date -Is) $name exited; restarting in 2 s" >>"$LOGS/supervisor.log"
      sleep 2
    done ) &
}

"$BIN/prefect" server start --host 127.0.0.1 --port "$PREFECT_PORT" >>"$LOGS/prefect-server.log" 2>&1 &
for _ in $(seq 1 90); do
  curl -sf "$PREFECT_API_URL/health" >/dev/null && break
  sleep 1
done
curl -sf "$PREFECT_API_URL/health" >/dev/null || { echo "Prefect server did not start; see $LOGS/prefect-server.log"; exit 1; }

"$BIN/siteline" init
if ! "$BIN/siteline" site show "$SITELINE_SITE" >/dev/null 2>&1; then
  # the demo site: 24 views a pair (the paper uses 300: `siteline site update demo --views 300`), auto scale and point size
  "$BIN/siteline" site create "$SITELINE_SITE" --crs EPSG:32618 --origin 445000 5030000 80 --fence deploy/demo-fence.geojson \
    --views 24
fi
"$BIN/prefect" work-pool create siteline-process --type process --overwrite >/dev/null
"$BIN/prefect" --no-prompt deploy --all --prefect-file deploy/prefect.yaml >>"$LOGS/deploy.log" 2>&1 \
  || { echo "prefect deploy failed; see $LOGS/deploy.log"; exit 1; }
"$BIN/python" -m deploy.service --pair-slots "$SITELINE_PAIR_SLOTS"
supervise prefect-worker "$BIN/prefect" worker start --pool siteline-process --name siteline-worker
supervise previews "$BIN/siteline" previews serve
supervise reporter "$BIN/python" -m deploy.reporter
supervise watcher "$BIN/siteline" watch "$SITELINE_WATCH_DIR" --site "$SITELINE_SITE" \
  --stable-seconds "${SITELINE_STABLE_SECONDS:-10}"
echo "UI: ${PREFECT_API_URL%/api}   previews: $SITELINE_PREVIEW_URL   logs: $LOGS"
echo "drop missions into $SITELINE_WATCH_DIR (site $SITELINE_SITE); Ctrl-C stops everything"
wait
