//! Fuzz target `normal_map`: see docs/FUZZING.md and `pomkit_io::fuzz_entry::normal_map`.
#![no_main]

use libfuzzer_sys::{Corpus, fuzz_target};
use pomkit_io::fuzz_entry::{Outcome, normal_map};

fuzz_target!(|data: &[u8]| -> Corpus {
    match normal_map(data) {
        Outcome::Skipped => Corpus::Reject,
        Outcome::Loaded | Outcome::Refused(_) => Corpus::Keep,
    }
});
