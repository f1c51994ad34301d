//! The plant: probe surfaces and fixed stops.
