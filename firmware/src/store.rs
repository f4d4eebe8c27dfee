//! Persistent parameter store (see below).
