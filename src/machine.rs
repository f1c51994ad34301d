//! Machine: channel + axes + link, built from a machine file.
