# Sourced by the wrk benchmarks: starts a real `planner-service serve` on 127.0.0.1:$port (temp
# data dir in $data, token in $FLEET_TOKEN), waits for /healthz, uploads the Nav2 depot map, and
# stops the service and removes the data dir on exit. Needs: $bin, $maps, $port.
export FLEET_TOKEN="wrk-bench-token-0123456789"
data="$(mktemp -d)"
"$bin" serve --listen "127.0.0.1:$port" --data-dir "$data" --zenoh-listen tcp/127.0.0.1:0 >"$data/serve.log" 2>&1 &
pid=$!
trap 'kill -TERM $pid 2>/dev/null; wait $pid 2>/dev/null; rm -rf "$data"' EXIT
for _ in $(seq 100); do curl -sf "http://127.0.0.1:$port/healthz" >/dev/null && break; sleep 0.1; done
curl -sf -H "Authorization: Bearer $FLEET_TOKEN" -F name=depot \
  -F "yaml=@$maps/depot.yaml" -F "image=@$maps/depot.pgm" "http://127.0.0.1:$port/api/v1/maps" >/dev/null
