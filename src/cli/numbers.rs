//! Value parsers for whole-number options, with messages that say what to give: the
//! library's ([`soda::app::numbers`]), which the model command line uses too.

pub use soda::app::numbers::{count, whole};
