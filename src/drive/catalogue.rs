//! Drive definition files (`drives/*.toml`).
