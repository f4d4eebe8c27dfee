//! Host-side simulator of the regenerative transducer and the tools around it.
pub mod diagnose;
