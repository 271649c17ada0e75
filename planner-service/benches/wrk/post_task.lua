-- wrk script: POST /api/v1/tasks with a one-goal task on the Nav2 `depot` map.
-- Env: FLEET_TOKEN (bearer token), GOAL_X_M / GOAL_Y_M (a free point; default one 1 m clear
-- of walls on depot). Every request stores a task (durable redb write) and publishes it.
local token = os.getenv("FLEET_TOKEN") or ""
local x = os.getenv("GOAL_X_M") or "1.525"
local y = os.getenv("GOAL_Y_M") or "14.075"
wrk.method = "POST"
wrk.headers["Content-Type"] = "application/json"
wrk.headers["Authorization"] = "Bearer " .. token
wrk.body = '{"map":"depot","goals":[{"x_m":' .. x .. ',"y_m":' .. y .. '}]}'

done = function(summary, latency, requests)
  io.write("non-2xx check: ", summary.errors.status, " bad statuses\n")
end
