-- wrk script: like post_task.lua, but each thread stops after STORE_PER_THREAD created tasks
-- (default 18400: two threads store the issue's 36.8k), to fill a store to a known size.
local token = os.getenv("FLEET_TOKEN") or ""
local x = os.getenv("GOAL_X_M") or "1.525"
local y = os.getenv("GOAL_Y_M") or "14.075"
local per_thread = tonumber(os.getenv("STORE_PER_THREAD") or "18400")
wrk.method = "POST"
wrk.headers["Content-Type"] = "application/json"
wrk.headers["Authorization"] = "Bearer " .. token
wrk.body = '{"map":"depot","goals":[{"x_m":' .. x .. ',"y_m":' .. y .. '}]}'

local created = 0
response = function(status, headers, body)
  if status == 201 then
    created = created + 1
  end
  if created >= per_thread then
    wrk.thread:stop()
  end
end
