//! Planner service: hybrid A* replanning, intentions (DLM, LPE), and the fleet HTTP API.
