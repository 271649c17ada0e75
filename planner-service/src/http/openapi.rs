//! The OpenAPI 3.1 description of the API, written by hand to match docs/api.md; served at
//! `GET /api/v1/openapi.json`. A test checks that its paths and methods are exactly those the
//! router serves.

use axum::Json;
use protocol::{MapName, RobotId};
use serde_json::{json, Value};

use super::ranges::{MAX_ABS_YAW_RAD, MAX_COORDINATE_M, MAX_RESOLUTION_M, MIN_RESOLUTION_M};

/// An id of at most `max_len` characters of `[A-Za-z0-9_.-]`, not starting with a dot (the
/// protocol's rule, which the server checks).
fn id_schema(max_len: usize) -> Value {
    json!({
        "type": "string", "minLength": 1, "maxLength": max_len,
        "pattern": format!("^[A-Za-z0-9_-][A-Za-z0-9_.-]{{0,{}}}$", max_len - 1)
    })
}

/// A map name (51 characters at most, so its id `<name>-<12 hex>` fits 64).
fn map_name() -> Value {
    id_schema(MapName::MAX_LEN)
}

/// A robot or task id.
fn id_pattern() -> Value {
    id_schema(RobotId::MAX_LEN)
}

/// A map-frame coordinate in metres, within the accepted range.
fn coordinate() -> Value {
    json!({ "type": "number", "minimum": -MAX_COORDINATE_M, "maximum": MAX_COORDINATE_M })
}

fn r(name: &str) -> Value {
    json!({ "$ref": format!("#/components/schemas/{name}") })
}

fn json_body(schema: Value) -> Value {
    json!({ "content": { "application/json": { "schema": schema } } })
}

fn ok(description: &str, schema: Value) -> Value {
    let mut v = json_body(schema);
    v["description"] = json!(description);
    v
}

fn err(name: &str) -> Value {
    json!({ "$ref": format!("#/components/responses/{name}") })
}

fn png(description: &str) -> Value {
    json!({
        "description": description,
        "content": { "image/png": { "schema": { "type": "string", "format": "binary" } } }
    })
}

fn path_param(name: &str, description: &str, schema: Value) -> Value {
    json!({ "name": name, "in": "path", "required": true, "description": description, "schema": schema })
}

fn query_param(name: &str, description: &str, schema: Value) -> Value {
    json!({ "name": name, "in": "query", "required": false, "description": description, "schema": schema })
}

fn upload_body(name_required: bool) -> Value {
    let required: Vec<&str> = if name_required { vec!["name"] } else { vec![] };
    json!({
        "required": true,
        "content": { "multipart/form-data": { "schema": {
            "type": "object",
            "description": "Either `yaml` + `image` (a ROS map_server map) or `picture` + `resolution_m` (a floor-plan picture).",
            "required": required,
            // The two kinds exclude each other: the server refuses a mix with a 400.
            "oneOf": [
                { "title": "ROS map", "required": ["yaml", "image"], "not": { "anyOf": [
                    { "required": ["picture"] }, { "required": ["resolution_m"] },
                    { "required": ["origin_x_m"] }, { "required": ["origin_y_m"] }
                ] } },
                { "title": "Floor-plan picture", "required": ["picture", "resolution_m"], "not": { "anyOf": [
                    { "required": ["yaml"] }, { "required": ["image"] }
                ] } }
            ],
            "properties": {
                "name": with_description(map_name(), "Map name: 1-51 characters of [A-Za-z0-9_.-], not starting with a dot."),
                "yaml": { "type": "string", "format": "binary", "description": "ROS map_server YAML; its `image` entry is replaced by the `image` part." },
                "image": { "type": "string", "format": "binary", "description": "The map image (PGM, PNG, BMP, JPEG)." },
                "picture": { "type": "string", "format": "binary", "description": "A floor-plan picture (PNG, JPEG, BMP, PGM)." },
                "resolution_m": { "type": "number", "minimum": MIN_RESOLUTION_M, "maximum": MAX_RESOLUTION_M, "description": "Metres per pixel of the picture." },
                "origin_x_m": with_description(coordinate(), "Map-frame x of the picture's lower-left corner (default 0)."),
                "origin_y_m": with_description(coordinate(), "Map-frame y of the picture's lower-left corner (default 0).")
            }
        } } }
    })
}

fn with_description(mut schema: Value, description: &str) -> Value {
    schema["description"] = json!(description);
    schema
}

fn schemas() -> Value {
    let num = json!({ "type": "number" });
    let uint = json!({ "type": "integer", "minimum": 0 });
    json!({
        "Error": {
            "type": "object", "required": ["error", "reason"],
            "properties": {
                "error": { "type": "string", "enum": ["bad_request", "unauthorized", "not_found", "method_not_allowed", "conflict", "too_large", "unsupported_media_type", "unavailable", "internal"] },
                "reason": { "type": "string", "description": "A sentence naming the field and value." }
            }
        },
        "Pose2D": {
            "type": "object", "required": ["x_m", "y_m", "yaw_rad"],
            "properties": { "x_m": num, "y_m": num, "yaw_rad": num }
        },
        "MapMeta": {
            "type": "object",
            "required": ["id", "name", "version", "content_hash", "width_cells", "height_cells", "resolution_m", "origin", "free_cells", "occupied_cells", "unknown_cells", "created_ns"],
            "properties": {
                "id": { "type": "string", "description": "<name>-<12 hex of the content hash>" },
                "name": { "type": "string" },
                "version": { "type": "integer", "minimum": 1 },
                "content_hash": { "type": "string", "description": "Hex sha256 of the geometry and cells." },
                "width_cells": uint, "height_cells": uint,
                "resolution_m": num,
                "origin": { "$ref": "#/components/schemas/Pose2D", "description": "Map-frame pose of the lower-left corner of cell (0, 0)." },
                "free_cells": uint, "occupied_cells": uint, "unknown_cells": uint,
                "created_ns": uint
            }
        },
        "MapRef": {
            "type": "object", "required": ["name", "version"],
            "properties": { "name": { "type": "string" }, "version": { "type": "integer", "minimum": 1 } }
        },
        "Goal": {
            "type": "object", "required": ["x_m", "y_m"], "additionalProperties": false,
            "properties": {
                "x_m": coordinate(), "y_m": coordinate(),
                "yaw_rad": {
                    "type": ["number", "null"], "minimum": -MAX_ABS_YAW_RAD, "maximum": MAX_ABS_YAW_RAD,
                    "description": "Absent or null: any heading."
                }
            }
        },
        "NewTask": {
            "type": "object", "required": ["map", "goals"], "additionalProperties": false,
            "properties": {
                "map": map_name(),
                "robot_id": {
                    "type": ["string", "null"], "minLength": 1, "maxLength": RobotId::MAX_LEN,
                    "pattern": id_pattern()["pattern"],
                    "description": "Absent or null: the nearest idle online robot on the map."
                },
                "goals": { "type": "array", "minItems": 1, "maxItems": 64, "items": r("Goal") }
            }
        },
        "TaskState": {
            "type": "object", "required": ["kind"],
            "description": "queued, assigned{robot_id}, active{robot_id,goal_index}, paused{robot_id,goal_index,reason}, completed, failed{reason}, cancelled",
            "properties": {
                "kind": { "type": "string", "enum": ["queued", "assigned", "active", "paused", "completed", "failed", "cancelled"] },
                "robot_id": { "type": "string" },
                "goal_index": uint,
                "reason": { "type": "string" }
            }
        },
        "HistoryEntry": {
            "type": "object", "required": ["stamp_ns", "state"],
            "properties": { "stamp_ns": uint, "state": r("TaskState") }
        },
        "Task": {
            "type": "object",
            "required": ["id", "map", "map_version", "robot_id", "goals", "state", "created_ns", "updated_ns", "history"],
            "properties": {
                "id": { "type": "string" },
                "map": { "type": "string" },
                "map_version": { "type": "integer", "minimum": 1 },
                "robot_id": { "type": ["string", "null"] },
                "goals": { "type": "array", "items": r("Goal") },
                "state": r("TaskState"),
                "created_ns": uint, "updated_ns": uint,
                "history": { "type": "array", "items": r("HistoryEntry") }
            }
        },
        "RobotPose": {
            "type": "object", "required": ["x_m", "y_m", "yaw_rad", "covariance", "stamp_ns"],
            "properties": {
                "x_m": num, "y_m": num, "yaw_rad": num,
                "covariance": { "type": "array", "items": num, "minItems": 9, "maxItems": 9, "description": "3x3 row-major over (x_m, y_m, yaw_rad)." },
                "stamp_ns": uint,
                "unmapped_obstacles_m": {
                    "type": "array", "maxItems": 256,
                    "items": { "type": "array", "items": num, "minItems": 2, "maxItems": 2 },
                    "description": "Map-frame points [x_m, y_m] the robot's laser sees standing where the floor plan is free; its plan keeps clear of them."
                }
            }
        },
        "StopReason": {
            "type": "object", "required": ["kind"],
            "properties": {
                "kind": { "type": "string", "enum": ["no_intention", "stale_intention", "localization_lost", "controller_error", "goal_reached", "collision", "commanded"] },
                "age_ms": uint, "position_std_m": num, "message": { "type": "string" }
            }
        },
        "RobotStatus": {
            "type": "object", "required": ["state", "stop_reason", "controller", "localized", "recovering", "backing_up", "rotating_in_place", "giving_way"],
            "properties": {
                "state": { "type": "string", "enum": ["starting", "idle", "driving", "stopping", "stopped", "relocalizing"] },
                "stop_reason": { "oneOf": [r("StopReason"), { "type": "null" }] },
                "controller": { "type": "string", "enum": ["dlm", "lpe", "none", "path-tracker", "dynamic-window"] },
                "localized": { "type": "boolean" },
                "recovering": { "type": "boolean", "description": "the agent's recovery drives in place of controller (stuck, held back by the collision monitor or short of the goal): the dynamic window, or backing straight off from someone met face to face" },
                "backing_up": { "type": "boolean", "description": "of recovering: the robot backs straight off the way it came from someone met face to face (no controller drives meanwhile)" },
                "rotating_in_place": { "type": "boolean", "description": "the rotation shim turns the robot on the spot towards its path before controller drives on" },
                "giving_way": { "type": "boolean", "description": "the give-way rule holds the robot short of a narrow passage while someone comes through it the other way" }
            }
        },
        "Intention": {
            "type": "object", "required": ["task_id", "goal_index", "dlm", "arriving", "path", "stamp_ns", "latency_ms"],
            "properties": {
                "task_id": { "type": ["string", "null"] },
                "goal_index": uint,
                "dlm": { "type": "string", "enum": ["turn_left", "turn_right", "go_forward", "stop"] },
                "arriving": { "type": "boolean", "description": "dlm is an arriving stop: the robot drives on to its goal" },
                "path": { "type": "array", "items": r("Pose2D") },
                "stamp_ns": uint,
                "latency_ms": num
            }
        },
        "Robot": {
            "type": "object",
            "required": ["id", "online", "last_seen_ns", "map", "pose", "status", "task_id", "intention"],
            "properties": {
                "id": { "type": "string" },
                "online": { "type": "boolean" },
                "last_seen_ns": uint,
                "map": { "oneOf": [r("MapRef"), { "type": "null" }] },
                "pose": { "oneOf": [r("RobotPose"), { "type": "null" }] },
                "status": { "oneOf": [r("RobotStatus"), { "type": "null" }] },
                "task_id": { "type": ["string", "null"] },
                "intention": { "oneOf": [r("Intention"), { "type": "null" }] }
            }
        },
        "Worker": {
            "type": "object",
            "required": ["id", "alive", "robots", "replans", "failures", "mean_latency_ms"],
            "description": "A replanning worker: `service` (the service process, which plans while no worker process is alive) or a `planner-service worker` process.",
            "properties": {
                "id": { "type": "string" },
                "alive": { "type": "boolean", "description": "Its liveliness token is up." },
                "robots": { "type": "array", "items": { "type": "string" }, "description": "Online robots whose last replanning cycle it ran." },
                "replans": uint,
                "failures": uint,
                "mean_latency_ms": { "type": "number", "minimum": 0 }
            }
        },
        "Health": {
            "type": "object", "required": ["status", "version", "robots_online", "tasks_active"],
            "properties": {
                "status": { "type": "string", "enum": ["ok"] },
                "version": { "type": "string" },
                "robots_online": uint,
                "tasks_active": uint
            }
        },
        "Snapshot": {
            "type": "object", "required": ["robots", "tasks"],
            "description": "SSE event `snapshot`, sent first.",
            "properties": {
                "robots": { "type": "array", "items": r("Robot") },
                "tasks": { "type": "array", "items": r("Task"), "description": "The tasks that have not ended (queued, assigned, active, paused), newest first, at most 1000. Finished ones: `GET /api/v1/tasks`." }
            }
        },
        "IntentionEvent": {
            "type": "object", "required": ["robot_id", "intention"],
            "description": "SSE event `intention`.",
            "properties": { "robot_id": { "type": "string" }, "intention": r("Intention") }
        }
    })
}

/// The whole document.
#[must_use]
pub fn document() -> Value {
    let bearer = json!([{ "bearer": [] }]);
    let read_security = json!([{}, { "bearer": [] }, { "access_token": [] }]);
    let name = path_param("name", "Map name.", map_name());
    let task_id = path_param("id", "Task id.", id_pattern());
    let robot_id = path_param("id", "Robot id.", id_pattern());
    json!({
        "openapi": "3.1.0",
        "info": {
            "title": "Intention fleet planner service",
            "version": env!("CARGO_PKG_VERSION"),
            "description": "Floor plans, delivery tasks, robots and the live event stream of the fleet (docs/api.md). Units in field names, angles in radians, poses in the map frame (REP-103). Mutating routes need `Authorization: Bearer <token>` (the scheme in any case); reads too when the service runs with `[http] protect_reads` (then also as `access_token=`). Numbers have physical ranges (coordinates within ±100 km, angles within ±2π rad, map resolutions 0.001-10 m per cell): beyond them a request is refused with 400 and nothing is stored. Connections: a request head must arrive within `[http] header_read_timeout_ms`, a connection on which nothing moves for `[http] idle_timeout_ms` is closed, and past `[http] max_connections` a new connection is answered 503 with `Retry-After`."
        },
        "security": read_security,
        "paths": {
            "/": { "get": {
                "summary": "The dashboard (HTML).", "security": [{}],
                "responses": { "200": { "description": "index.html", "content": { "text/html": { "schema": { "type": "string" } } } } }
            } },
            "/assets/app.js": { "get": {
                "summary": "Dashboard script.", "security": [{}],
                "responses": { "200": { "description": "JavaScript module", "content": { "text/javascript": { "schema": { "type": "string" } } } } }
            } },
            "/assets/style.css": { "get": {
                "summary": "Dashboard style sheet.", "security": [{}],
                "responses": { "200": { "description": "CSS", "content": { "text/css": { "schema": { "type": "string" } } } } }
            } },
            "/healthz": { "get": {
                "summary": "Liveness, robots online, tasks active.", "security": [{}],
                "responses": { "200": ok("Healthy.", r("Health")) }
            } },
            "/metrics": { "get": {
                "summary": "Prometheus metrics (replan latency histogram, replans, robots, tasks, HTTP requests).",
                "responses": {
                    "200": { "description": "Prometheus text format 0.0.4", "content": { "text/plain": { "schema": { "type": "string" } } } },
                    "401": err("Unauthorized")
                }
            } },
            "/api/v1/openapi.json": { "get": {
                "summary": "This document.",
                "responses": { "200": ok("OpenAPI 3.1 document.", json!({ "type": "object" })), "401": err("Unauthorized") }
            } },
            "/api/v1/maps": {
                "get": {
                    "summary": "The latest version of every map.",
                    "responses": { "200": ok("Maps by name.", json!({ "type": "array", "items": r("MapMeta") })), "401": err("Unauthorized") }
                },
                "post": {
                    "summary": "Upload a floor plan (ROS map or picture); stores a new version.",
                    "security": bearer,
                    "requestBody": upload_body(true),
                    "responses": {
                        "201": ok("Stored as a new version.", r("MapMeta")),
                        "200": ok("Identical content was already stored under this name: that version.", r("MapMeta")),
                        "400": err("BadRequest"), "401": err("Unauthorized"), "413": err("TooLarge"), "503": err("Busy")
                    }
                }
            },
            "/api/v1/maps/preview": { "post": {
                "summary": "The occupancy image an upload would store; stores nothing.",
                "security": bearer,
                "requestBody": upload_body(false),
                "responses": {
                    "200": {
                        "description": "Free white, occupied black, unknown grey; top of the image = +y.",
                        "headers": {
                            "x-map-width": { "schema": { "type": "integer" } },
                            "x-map-height": { "schema": { "type": "integer" } },
                            "x-map-resolution-m": { "schema": { "type": "number" } }
                        },
                        "content": { "image/png": { "schema": { "type": "string", "format": "binary" } } }
                    },
                    "400": err("BadRequest"), "401": err("Unauthorized"), "413": err("TooLarge"), "503": err("Busy")
                }
            } },
            "/api/v1/maps/{name}": { "get": {
                "summary": "Metadata of the latest version.",
                "parameters": [name],
                "responses": { "200": ok("The latest version.", r("MapMeta")), "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound") }
            } },
            "/api/v1/maps/{name}/versions": { "get": {
                "summary": "Every version, oldest first.",
                "parameters": [name],
                "responses": { "200": ok("Versions.", json!({ "type": "array", "items": r("MapMeta") })), "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound") }
            } },
            "/api/v1/maps/{name}/image": { "get": {
                "summary": "The occupancy grid as PNG (as preview).",
                "parameters": [name, query_param("version", "Version (default: latest).", json!({ "type": "integer", "minimum": 1, "maximum": u32::MAX }))],
                "responses": { "200": png("Free white, occupied black, unknown grey; top = +y; x-map-* headers as preview. `ETag` is the map id (content addressed); rendered once per version and kept (`[http] image_cache_bytes`)."), "304": { "description": "`If-None-Match` names this version's ETag: the client's copy is current." }, "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound") }
            } },
            "/api/v1/tasks": {
                "get": {
                    "summary": "Tasks, newest first.",
                    "parameters": [
                        query_param("state", "Only tasks in this state.", json!({ "type": "string", "enum": ["queued", "assigned", "active", "paused", "completed", "failed", "cancelled"] })),
                        query_param("robot_id", "Only tasks of this robot.", id_pattern()),
                        query_param("map", "Only tasks on this map.", map_name()),
                        query_param("limit", "At most this many (default 100).", json!({ "type": "integer", "minimum": 1, "maximum": 1000 })),
                        query_param("cursor", "Start after this task: the `Next-Cursor` header of the previous page (opaque: a value matching the pattern is a position in the newest-first order; other values are a 400). Combine with the same filters.", json!({ "type": "string", "pattern": crate::fleet::Cursor::PATTERN, "minLength": 18, "maxLength": crate::fleet::Cursor::MAX_TEXT_LEN }))
                    ],
                    "responses": { "200": {
                        "description": "Tasks, newest first (by creation time, then id). Each page costs about `limit` lookups, whatever the number of tasks stored.",
                        "headers": { "Next-Cursor": { "description": "Present when more tasks match: pass it as `cursor` for the next page. Absent on the last page.", "schema": { "type": "string" } } },
                        "content": { "application/json": { "schema": { "type": "array", "items": r("Task") } } }
                    }, "400": err("BadRequest"), "401": err("Unauthorized") }
                },
                "post": {
                    "summary": "Create a delivery task (1-64 goals on the map, in free space).",
                    "security": bearer,
                    "requestBody": { "required": true, "content": { "application/json": { "schema": r("NewTask") } } },
                    "responses": {
                        "201": ok("Created (queued or assigned).", r("Task")),
                        "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound"),
                        "409": err("Conflict"), "413": err("TooLarge")
                    }
                }
            },
            "/api/v1/tasks/{id}": { "get": {
                "summary": "One task.",
                "parameters": [task_id],
                "responses": { "200": ok("The task.", r("Task")), "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound") }
            } },
            "/api/v1/tasks/{id}/cancel": { "post": {
                "summary": "Cancel a task that has not ended; its robot gets a Stop intention.",
                "security": bearer,
                "parameters": [task_id],
                "responses": { "200": ok("Cancelled.", r("Task")), "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound"), "409": err("Conflict") }
            } },
            "/api/v1/robots": { "get": {
                "summary": "Every known robot, sorted by id.",
                "responses": { "200": ok("Robots.", json!({ "type": "array", "items": r("Robot") })), "401": err("Unauthorized") }
            } },
            "/api/v1/workers": { "get": {
                "summary": "The replanning workers (the service and the worker processes) and the robots each plans.",
                "responses": { "200": ok("Workers, sorted by id.", json!({ "type": "array", "items": r("Worker") })), "401": err("Unauthorized") }
            } },
            "/api/v1/robots/{id}": { "get": {
                "summary": "One robot.",
                "parameters": [robot_id],
                "responses": { "200": ok("The robot.", r("Robot")), "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound") }
            } },
            "/api/v1/robots/{id}/lpe.png": { "get": {
                "summary": "The LPE image of the robot's latest intention.",
                "parameters": [robot_id],
                "responses": { "200": png("224 x 224 LPE image."), "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound") }
            } },
            "/api/v1/robots/{id}/camera.jpg": { "get": {
                "summary": "The robot's latest sampled camera frame.",
                "parameters": [robot_id],
                "responses": {
                    "200": { "description": "JPEG", "content": { "image/jpeg": { "schema": { "type": "string", "format": "binary" } } } },
                    "400": err("BadRequest"), "401": err("Unauthorized"), "404": err("NotFound")
                }
            } },
            "/api/v1/events": { "get": {
                "summary": "Live events (Server-Sent Events): `snapshot` first, then `robot`, `intention`, `task`; `: keep-alive` every 15 s.",
                "responses": {
                    "200": {
                        "description": "text/event-stream; each event has an `event:` name and one JSON `data:` line: snapshot → Snapshot, robot → Robot, intention → IntentionEvent, task → Task.",
                        "content": { "text/event-stream": { "schema": { "type": "string" },
                            "x-events": { "snapshot": r("Snapshot"), "robot": r("Robot"), "intention": r("IntentionEvent"), "task": r("Task") } } }
                    },
                    "401": err("Unauthorized")
                }
            } }
        },
        "components": {
            "securitySchemes": {
                "bearer": { "type": "http", "scheme": "bearer" },
                "access_token": { "type": "apiKey", "in": "query", "name": "access_token", "description": "Reads only, for EventSource and <img>." }
            },
            "responses": {
                "BadRequest": { "description": "Malformed or invalid input; nothing was changed.", "content": { "application/json": { "schema": r("Error") } } },
                "Unauthorized": { "description": "Missing or wrong token.", "content": { "application/json": { "schema": r("Error") } } },
                "NotFound": { "description": "Unknown map, version, task or robot.", "content": { "application/json": { "schema": r("Error") } } },
                "Conflict": { "description": "The task already ended, or the robot is busy or on another map.", "content": { "application/json": { "schema": r("Error") } } },
                "TooLarge": { "description": "Body over the upload limit, image over the import limits, or a picture whose decode needs more memory than `[http] decode_budget_bytes`.", "content": { "application/json": { "schema": r("Error") } } },
                "Busy": { "description": "Other floor plans are being decoded and this one did not fit in the decode budget within `[http] decode_wait_ms`; try again after `Retry-After` seconds.", "headers": { "Retry-After": { "schema": { "type": "integer", "minimum": 1 } } }, "content": { "application/json": { "schema": r("Error") } } }
            },
            "schemas": schemas()
        }
    })
}

/// `GET /api/v1/openapi.json`.
pub async fn openapi_json() -> Json<Value> {
    Json(document())
}
