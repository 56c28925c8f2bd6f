//! Fuzz target `rays`: see docs/FUZZING.md and `pomkit_io::fuzz_entry::rays`.
#![no_main]

use libfuzzer_sys::{Corpus, fuzz_target};
use pomkit_io::fuzz_entry::{Outcome, rays};

fuzz_target!(|data: &[u8]| -> Corpus {
    match rays(data) {
        Outcome::Skipped => Corpus::Reject,
        Outcome::Loaded | Outcome::Refused(_) => Corpus::Keep,
    }
});
