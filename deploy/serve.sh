#!/usr/bin/env bash
# Start the Prefect server (UI on http://127.0.0.1:4200), the siteline deployments and their process
# work pool, a worker, and the upload watcher. Stop everything with Ctrl-C.
#
#   SITELINE_HOME       catalog and stores (default ./serve-home)
#   SITELINE_WATCH_DIR  folder to drop mission uploads into (default $SITELINE_HOME/uploads)
#   SITELINE_SITE       site the uploads belong to (default demo; created from the synthetic fence if missing)
#   SITELINE_RELEASE_POLICY  every-pair (default here) or on-demand
#   SITELINE_STORE_URL  data stores: a folder or an fsspec URL such as s3://bucket/siteline (default $SITELINE_HOME/stores)
#   PostgreSQL instead of SQLite, for both: deploy/postgres.env (see docs in it).
#   Workers on several machines (PostgreSQL, an object store, Dask): deploy/shared.env.
set -euo pipefail
cd "$(dirname "$0")/.."
export SITELINE_REPO="$PWD"
export SITELINE_HOME="${SITELINE_HOME:-$PWD/serve-home}"
export SITELINE_WATCH_DIR="${SITELINE_WATCH_DIR:-$SITELINE_HOME/uploads}"
export SITELINE_SITE="${SITELINE_SITE:-demo}"
export SITELINE_RELEASE_POLICY="${SITELINE_RELEASE_POLICY:-every-pair}"
export PREFECT_HOME="${PREFECT_HOME:-$SITELINE_HOME/prefect}"
export PREFECT_API_URL="${PREFECT_API_URL:-http://127.0.0.1:4200/api}"
export PREFECT_SERVER_ANALYTICS_ENABLED=false
export PREFECT_UI_API_URL="$PREFECT_API_URL"
BIN="$PWD/.venv/bin"
mkdir -p "$SITELINE_HOME" "$SITELINE_WATCH_DIR" "$PREFECT_HOME"

pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; }
trap cleanup EXIT INT TERM

"$BIN/prefect" server start --host 127.0.0.1 --port 4200 >"$SITELINE_HOME/prefect-server.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 60); do
  curl -sf "$PREFECT_API_URL/health" >/dev/null && break
  sleep 1
done
curl -sf "$PREFECT_API_URL/health" >/dev/null || { echo "Prefect server did not start; see $SITELINE_HOME/prefect-server.log"; exit 1; }

"$BIN/siteline" init
if ! "$BIN/siteline" site show "$SITELINE_SITE" >/dev/null 2>&1; then
  "$BIN/siteline" site create "$SITELINE_SITE" --crs EPSG:32618 --origin 445000 5030000 80 --fence deploy/demo-fence.geojson
fi
"$BIN/prefect" work-pool create siteline-process --type process --overwrite >/dev/null
"$BIN/prefect" --no-prompt deploy --all --prefect-file deploy/prefect.yaml
"$BIN/prefect" worker start --pool siteline-process >"$SITELINE_HOME/prefect-worker.log" 2>&1 &
pids+=($!)
echo "UI: http://127.0.0.1:4200   drop missions into $SITELINE_WATCH_DIR (site $SITELINE_SITE)"
"$BIN/siteline" watch "$SITELINE_WATCH_DIR" --site "$SITELINE_SITE" --stable-seconds "${SITELINE_STABLE_SECONDS:-10}" &
pids+=($!)
wait
