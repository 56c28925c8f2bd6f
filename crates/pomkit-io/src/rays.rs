//! Rays files, read as a stream: CSV with the header `u,v,dx,dy,dz`, then one ray per line
//! (the entry point in UV and the direction of travel; see `pomkit trace --help`).
//!
//! [`RayReader`] reads one line at a time, so any number of rays takes bounded memory. A line
//! longer than [`MAX_LINE`] bytes is an error naming the line (read no further than the limit),
//! and so is a NUL byte (binary data such as `/dev/zero` fails within its first line). Blank
//! lines are skipped; a UTF-8 byte-order mark before the header is allowed; every other problem
//! is an error naming the input and the line.

use std::io::BufRead;

use pomkit_core::Ray;
use pomkit_core::glam::{Vec2, Vec3};

/// The columns of a rays file's header.
pub const RAYS_HEADER: [&str; 5] = ["u", "v", "dx", "dy", "dz"];

/// The longest line accepted, in bytes (without its line ending). Five floats written out in
/// full take well under 100 bytes; this leaves room for padding and long decimal forms.
pub const MAX_LINE: usize = 4096;

/// What is wrong with a rays file. Every variant names the input and, past the header, the line.
#[derive(Debug, thiserror::Error)]
pub enum RaysError {
    /// Nothing at all, not even a header.
    #[error("{name} is empty: expected the header line u,v,dx,dy,dz")]
    Empty {
        /// The input.
        name: String,
    },
    /// The first line is not the header.
    #[error("{name}: line 1: the header is '{found}', expected 'u,v,dx,dy,dz'")]
    Header {
        /// The input.
        name: String,
        /// The first line, trimmed.
        found: String,
    },
    /// A line does not have five fields.
    #[error("{name}: line {line}: expected 5 values (u,v,dx,dy,dz), found {found}")]
    FieldCount {
        /// The input.
        name: String,
        /// 1-based line number.
        line: u64,
        /// How many comma-separated fields it has.
        found: usize,
    },
    /// A field is not a number.
    #[error("{name}: line {line}: {column} '{text}' is not a number")]
    NotANumber {
        /// The input.
        name: String,
        /// 1-based line number.
        line: u64,
        /// The column's name (u, v, dx, dy, dz).
        column: &'static str,
        /// The field, trimmed.
        text: String,
    },
    /// A field is infinite or NaN (or overflows f32).
    #[error("{name}: line {line}: {column} '{text}' is not finite (values must be finite numbers)")]
    NotFinite {
        /// The input.
        name: String,
        /// 1-based line number.
        line: u64,
        /// The column's name.
        column: &'static str,
        /// The field, trimmed.
        text: String,
    },
    /// A line is longer than [`MAX_LINE`] bytes.
    #[error("{name}: line {line} is longer than {MAX_LINE} bytes: this is not a rays file (u,v,dx,dy,dz per line)")]
    LineTooLong {
        /// The input.
        name: String,
        /// 1-based line number.
        line: u64,
    },
    /// A line holds a NUL byte: binary data.
    #[error("{name}: line {line} contains a NUL byte: this is binary data, not a CSV rays file")]
    Binary {
        /// The input.
        name: String,
        /// 1-based line number.
        line: u64,
    },
    /// A line is not UTF-8 text.
    #[error("{name}: line {line}: not UTF-8 text (byte {byte} of the line)")]
    NotUtf8 {
        /// The input.
        name: String,
        /// 1-based line number.
        line: u64,
        /// 0-based offset of the first invalid byte within the line.
        byte: usize,
    },
    /// Reading failed.
    #[error("cannot read rays from {name} at line {line}: {reason}")]
    Read {
        /// The input.
        name: String,
        /// 1-based line number being read.
        line: u64,
        /// The operating system's reason.
        reason: std::io::Error,
    },
}

/// Reads rays one line at a time from a rays file (see the [module docs](self)).
///
/// After the first error the iterator ends.
pub struct RayReader<R: BufRead> {
    reader: R,
    name: String,
    /// The number of the last line read (1 is the header).
    line: u64,
    buf: Vec<u8>,
    done: bool,
}

impl<R: BufRead> RayReader<R> {
    /// Reads and checks the header line of `reader`; `name` names the input in errors.
    ///
    /// # Errors
    /// [`RaysError::Empty`] for no input, [`RaysError::Header`] for a wrong header, or a
    /// line error (too long, binary, not UTF-8, unreadable) for line 1.
    pub fn new(reader: R, name: &str) -> Result<Self, RaysError> {
        let mut me = Self { reader, name: name.to_owned(), line: 0, buf: Vec::new(), done: false };
        if !me.read_line()? {
            return Err(RaysError::Empty { name: me.name });
        }
        let header = me.text()?;
        let header = header.strip_prefix('\u{feff}').unwrap_or(header);
        if !header.split(',').map(str::trim).eq(RAYS_HEADER) {
            return Err(RaysError::Header { name: me.name.clone(), found: header.trim().to_owned() });
        }
        Ok(me)
    }

    /// The name given to [`RayReader::new`].
    #[must_use]
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Reads the next line into `buf` without its line ending; false at the end of the input.
    fn read_line(&mut self) -> Result<bool, RaysError> {
        self.buf.clear();
        self.line += 1;
        let mut any = false;
        loop {
            let available = match self.reader.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(reason) => return Err(RaysError::Read { name: self.name.clone(), line: self.line, reason }),
            };
            if available.is_empty() {
                break;
            }
            any = true;
            let (part, used, end) = match available.iter().position(|&b| b == b'\n') {
                Some(i) => (&available[..i], i + 1, true),
                None => (available, available.len(), false),
            };
            if part.contains(&0) {
                return Err(RaysError::Binary { name: self.name.clone(), line: self.line });
            }
            if self.buf.len() + part.len() > MAX_LINE + 1 {
                // +1: a '\r' before the '\n' does not count.
                return Err(RaysError::LineTooLong { name: self.name.clone(), line: self.line });
            }
            self.buf.extend_from_slice(part);
            self.reader.consume(used);
            if end {
                break;
            }
        }
        if self.buf.last() == Some(&b'\r') {
            self.buf.pop();
        }
        if self.buf.len() > MAX_LINE {
            return Err(RaysError::LineTooLong { name: self.name.clone(), line: self.line });
        }
        Ok(any)
    }

    /// The current line as text.
    fn text(&self) -> Result<&str, RaysError> {
        std::str::from_utf8(&self.buf).map_err(|e| RaysError::NotUtf8 {
            name: self.name.clone(),
            line: self.line,
            byte: e.valid_up_to(),
        })
    }

    /// Parses the current line: `None` for a blank one.
    fn parse_line(&self) -> Result<Option<Ray>, RaysError> {
        let line = self.text()?;
        if line.trim().is_empty() {
            return Ok(None);
        }
        let (name, n) = (&self.name, self.line);
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != RAYS_HEADER.len() {
            return Err(RaysError::FieldCount { name: name.clone(), line: n, found: fields.len() });
        }
        let mut v = [0.0f32; 5];
        for ((slot, text), column) in v.iter_mut().zip(&fields).zip(RAYS_HEADER) {
            let text = text.trim();
            let x: f32 = text.parse().map_err(|_| RaysError::NotANumber {
                name: name.clone(),
                line: n,
                column,
                text: text.to_owned(),
            })?;
            if !x.is_finite() {
                return Err(RaysError::NotFinite { name: name.clone(), line: n, column, text: text.to_owned() });
            }
            *slot = x;
        }
        Ok(Some(Ray::new(Vec2::new(v[0], v[1]), Vec3::new(v[2], v[3], v[4]))))
    }
}

impl<R: BufRead> Iterator for RayReader<R> {
    type Item = Result<Ray, RaysError>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let step = self.read_line().and_then(|more| if more { self.parse_line().map(Some) } else { Ok(None) });
            match step {
                Ok(Some(Some(ray))) => return Some(Ok(ray)),
                Ok(Some(None)) => {} // a blank line
                Ok(None) => self.done = true,
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
        }
        None
    }
}

/// Parses the whole text of a rays file called `name` (for messages).
///
/// # Errors
/// The first [`RaysError`] in the text.
pub fn parse_rays(text: &str, name: &str) -> Result<Vec<Ray>, RaysError> {
    RayReader::new(text.as_bytes(), name)?.collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_rays_and_reports_bad_lines() {
        let rays = parse_rays("\u{feff}u, v,dx,dy,dz\r\n0.5,0.25,1,0,-1\r\n\r\n1e-3,2,0,-0.5,-2\n", "r.csv").unwrap();
        assert_eq!(rays.len(), 2);
        assert_eq!(rays[1], Ray::new(Vec2::new(1e-3, 2.0), Vec3::new(0.0, -0.5, -2.0)));
        assert!(parse_rays("u,v,dx,dy,dz\n", "r.csv").unwrap().is_empty());
        assert_eq!(parse_rays("u,v,dx,dy,dz\n1,2,3,4,-5", "r.csv").unwrap().len(), 1, "no final newline");
        let err = |t: &str| parse_rays(t, "r.csv").unwrap_err().to_string();
        assert_eq!(err(""), "r.csv is empty: expected the header line u,v,dx,dy,dz");
        assert_eq!(err("u,v,dz\n"), "r.csv: line 1: the header is 'u,v,dz', expected 'u,v,dx,dy,dz'");
        assert!(err("u,v,dx,dy,dz\n0,0,0,0,-1\n0,0,1,-1\n").contains("line 3: expected 5 values"));
        let e = err("u,v,dx,dy,dz\n0,0,0,0,-1\n0,0,x,0,-1\n");
        assert!(e.contains("line 3") && e.contains("dx 'x' is not a number"), "{e}");
        assert!(err("u,v,dx,dy,dz\n0,NaN,0,0,-1\n").contains("line 2: v 'NaN' is not finite"));
        assert!(err("u,v,dx,dy,dz\n0,0,0,1e39,-1\n").contains("dy '1e39' is not finite"));
        assert!(err("u,v,dx,dy,dz\n0,0,0,0,-inf\n").contains("line 2"));
        assert!(err("u,v,dx,dy,dz\n0,0,0,0,-1\n0,\u{0}0,0,0,-1\n").contains("line 3 contains a NUL byte"));
        let e = parse_rays("u,v,dx,dy,dz\n", "r.csv").map(|_| ());
        assert!(e.is_ok());
        let bad_utf8 = RayReader::new(&b"u,v,dx,dy,dz\n0,0,\xff,0,-1\n"[..], "r.csv").unwrap().next().unwrap();
        assert!(bad_utf8.unwrap_err().to_string().contains("line 2: not UTF-8"));
    }

    #[test]
    fn long_lines_and_binary_fail_without_reading_on() {
        // A line at the limit is fine; one byte more is an error naming the line.
        let pad = " ".repeat(MAX_LINE - "0,0,0,0,-1".len());
        assert_eq!(parse_rays(&format!("u,v,dx,dy,dz\n0,0,0,0,-1{pad}\n"), "r").unwrap().len(), 1);
        let e = parse_rays(&format!("u,v,dx,dy,dz\n0,0,0,0,-1{pad} \n"), "r").unwrap_err().to_string();
        assert!(e.contains("r: line 2 is longer than 4096 bytes"), "{e}");

        /// An endless reader that counts what is taken from it.
        struct Endless {
            byte: u8,
            taken: std::rc::Rc<std::cell::Cell<usize>>,
            buf: [u8; 8192],
        }
        impl std::io::Read for Endless {
            fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
                out.fill(self.byte);
                self.taken.set(self.taken.get() + out.len());
                Ok(out.len())
            }
        }
        impl BufRead for Endless {
            fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
                self.buf.fill(self.byte);
                Ok(&self.buf)
            }
            fn consume(&mut self, n: usize) {
                self.taken.set(self.taken.get() + n);
            }
        }
        let taken = std::rc::Rc::new(std::cell::Cell::new(0));
        let zeros = Endless { byte: 0, taken: taken.clone(), buf: [0; 8192] };
        let e = RayReader::new(zeros, "/dev/zero").err().unwrap().to_string();
        assert_eq!(e, "/dev/zero: line 1 contains a NUL byte: this is binary data, not a CSV rays file");
        assert_eq!(taken.get(), 0);
        let taken = std::rc::Rc::new(std::cell::Cell::new(0));
        let xs = Endless { byte: b'x', taken: taken.clone(), buf: [0; 8192] };
        let e = RayReader::new(xs, "<stdin>").err().unwrap().to_string();
        assert!(e.contains("<stdin>: line 1 is longer than 4096 bytes"), "{e}");
        assert!(taken.get() <= 2 * 8192, "read {} bytes", taken.get());
    }
}
