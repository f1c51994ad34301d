//! PDO layouts.
