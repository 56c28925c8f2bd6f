//! Fuzz target `batch_config`: see docs/FUZZING.md and `pomkit_io::fuzz_entry::batch_config`.
#![no_main]

use libfuzzer_sys::{Corpus, fuzz_target};
use pomkit_io::fuzz_entry::{Outcome, batch_config};

fuzz_target!(|data: &[u8]| -> Corpus {
    match batch_config(data) {
        Outcome::Skipped => Corpus::Reject,
        Outcome::Loaded | Outcome::Refused(_) => Corpus::Keep,
    }
});
