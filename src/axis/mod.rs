//! One axis: parameters, drive adapter, state.
