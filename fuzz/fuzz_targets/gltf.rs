//! Fuzz target `gltf`: see docs/FUZZING.md and `pomkit_io::fuzz_entry::gltf`.
#![no_main]

use libfuzzer_sys::{Corpus, fuzz_target};
use pomkit_io::fuzz_entry::{Outcome, gltf};

fuzz_target!(|data: &[u8]| -> Corpus {
    match gltf(data) {
        Outcome::Skipped => Corpus::Reject,
        Outcome::Loaded | Outcome::Refused(_) => Corpus::Keep,
    }
});
