//! Path segments (lines, arcs, helices) with exact extents.
