//! Hostile slots (filled in below).
