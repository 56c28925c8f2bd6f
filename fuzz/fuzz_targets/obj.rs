//! Fuzz target `obj`: see docs/FUZZING.md and `pomkit_io::fuzz_entry::obj`.
#![no_main]

use libfuzzer_sys::{Corpus, fuzz_target};
use pomkit_io::fuzz_entry::{Outcome, obj};

fuzz_target!(|data: &[u8]| -> Corpus {
    match obj(data) {
        Outcome::Skipped => Corpus::Reject,
        Outcome::Loaded | Outcome::Refused(_) => Corpus::Keep,
    }
});
