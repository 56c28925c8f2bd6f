//! Fuzz target `scene`: see docs/FUZZING.md and `pomkit_io::fuzz_entry::scene`.
#![no_main]

use libfuzzer_sys::{Corpus, fuzz_target};
use pomkit_io::fuzz_entry::{Outcome, scene};

fuzz_target!(|data: &[u8]| -> Corpus {
    match scene(data) {
        Outcome::Skipped => Corpus::Reject,
        Outcome::Loaded | Outcome::Refused(_) => Corpus::Keep,
    }
});
