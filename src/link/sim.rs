//! In-memory link to drive models.
