//! Fuzz target `height_image`: see docs/FUZZING.md and `pomkit_io::fuzz_entry::height_image`.
#![no_main]

use libfuzzer_sys::{Corpus, fuzz_target};
use pomkit_io::fuzz_entry::{Outcome, height_image};

fuzz_target!(|data: &[u8]| -> Corpus {
    match height_image(data) {
        Outcome::Skipped => Corpus::Reject,
        Outcome::Loaded | Outcome::Refused(_) => Corpus::Keep,
    }
});
