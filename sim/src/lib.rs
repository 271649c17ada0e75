//! Simulator: the ground-truth world, a differential-drive base and its sensors.
