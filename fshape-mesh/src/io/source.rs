//! Opening input files within bounds set by the input itself.
//!
//! A reader must not be walked into unbounded memory or time by a file it
//! was handed: a device (`/dev/zero`), a FIFO, a decompression bomb, or a
//! header that claims a billion values. The rules, in the order applied:
//!
//! - a path is checked by its metadata *before* it is opened: folders,
//!   devices and sockets are refused (opening a FIFO blocks, reading a
//!   device never ends); regular files and pipes (`--signal <(zcat t.gz)`)
//!   are read;
//! - a pipe is read up to [`Limits::max_stream_bytes`];
//! - gzip and bzip2 data may expand at most [`EXPANSION`] times past a
//!   floor of [`EXPANSION_FLOOR`] bytes (real surfaces and signals compress
//!   2–3 times; a bomb compresses a thousand times), unless the user sets a
//!   byte limit of their own;
//! - the first bytes must be those of the format expected, so that a stream
//!   of zeros or random bytes is refused after a few kilobytes;
//! - a header's counts are checked against the bytes that follow and
//!   against [`Limits::max_values`] before anything is allocated (in each
//!   format's parser).
//!
//! The limits come from the environment (`FSHAPE_MAX_VALUES`,
//! `FSHAPE_MAX_BYTES`, `FSHAPE_EXTERNAL_DATA_ANYWHERE`), or from
//! [`set_limits`] before the first read.

use std::fs::File;
use std::io::{self, Read};
use std::path::Path;
use std::sync::OnceLock;

use super::{Format, Location, ParseError, ParseErrorKind, ReadError};

/// How many times compressed data may expand past [`EXPANSION_FLOOR`].
pub const EXPANSION: u64 = 32;

/// Decompressed bytes always allowed, whatever the compression ratio
/// (a constant signal on a large mesh compresses several hundred times).
pub const EXPANSION_FLOOR: u64 = 16 << 20;

/// Bounds on what a reader will hold.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Limits {
    /// Values (coordinates, indices, signal values) a header may declare
    /// for one array: 2³¹ by default (`FSHAPE_MAX_VALUES`).
    pub max_values: u64,
    /// Bytes read from a pipe or out of a decompressor. `None`: 4 GiB from
    /// a pipe, and [`EXPANSION`] times the compressed size (at least
    /// [`EXPANSION_FLOOR`]) out of a decompressor. `FSHAPE_MAX_BYTES`
    /// sets it, for both.
    pub max_stream_bytes: Option<u64>,
    /// Whether a GIfTI file may name external data files outside its own
    /// folder (an absolute name or one with `..`): off by default, so that
    /// a `.gii` cannot pull any readable file into a signal or a report
    /// (`FSHAPE_EXTERNAL_DATA_ANYWHERE=1`).
    pub external_data_anywhere: bool,
}

/// Bytes read from a pipe when [`Limits::max_stream_bytes`] is `None`.
pub const PIPE_BYTES: u64 = 4 << 30;

impl Default for Limits {
    fn default() -> Self {
        Limits { max_values: 1 << 31, max_stream_bytes: None, external_data_anywhere: false }
    }
}

impl Limits {
    /// The defaults, overridden by the environment variables named on the
    /// fields; an unreadable value is ignored with a warning on stderr.
    pub fn from_env() -> Limits {
        let mut l = Limits::default();
        let number = |name: &str| {
            let v = std::env::var(name).ok()?;
            match v.trim().parse::<u64>() {
                Ok(n) if n > 0 => Some(n),
                _ => {
                    eprintln!("warning: {name}={v} is not a positive whole number; ignored");
                    None
                }
            }
        };
        if let Some(n) = number("FSHAPE_MAX_VALUES") {
            l.max_values = n;
        }
        l.max_stream_bytes = number("FSHAPE_MAX_BYTES");
        l.external_data_anywhere =
            std::env::var("FSHAPE_EXTERNAL_DATA_ANYWHERE").is_ok_and(|v| matches!(v.trim(), "1" | "true" | "yes"));
        l
    }
}

static LIMITS: OnceLock<Limits> = OnceLock::new();

/// The limits in force: those given to [`set_limits`], else
/// [`Limits::from_env`].
pub fn limits() -> &'static Limits {
    LIMITS.get_or_init(Limits::from_env)
}

/// Sets the limits for the rest of the process; returns false (and changes
/// nothing) if they were already set or used.
pub fn set_limits(limits: Limits) -> bool {
    LIMITS.set(limits).is_ok()
}

/// Refuses a declared count above [`Limits::max_values`] (before anything
/// is allocated for it).
pub(crate) fn check_values(n: u64, what: &'static str) -> Result<(), ParseErrorKind> {
    let limit = limits().max_values;
    if n > limit { Err(ParseErrorKind::TooMany { what, claimed: n, limit }) } else { Ok(()) }
}

/// What the caller expects a file to hold, checked on its first bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Expect {
    /// A mesh in this format.
    Mesh(Format),
    /// A signal: CSV, GIfTI, FreeSurfer curv or MGH.
    Signal,
    /// Text (CSV tables).
    Text,
    /// Anything (images: their own decoder checks).
    Any,
}

/// Bytes looked at before the rest is read.
const PREFIX: usize = 4096;

/// An input opened within bounds: its first bytes (already decompressed and
/// checked) and a reader for the rest.
pub(crate) struct Input {
    pub(crate) prefix: Vec<u8>,
    pub(crate) rest: Box<dyn Read>,
    /// The size of the whole decompressed data, when known (an uncompressed
    /// regular file): a capacity hint.
    pub(crate) size_hint: Option<u64>,
}

impl Input {
    /// The whole data.
    pub(crate) fn read_all(mut self, path: &Path) -> Result<Vec<u8>, ReadError> {
        let mut out = self.prefix;
        if let Some(n) = self.size_hint {
            out.reserve_exact((n as usize).saturating_sub(out.len()));
        }
        self.rest.read_to_end(&mut out).map_err(|source| ReadError::Io { path: path.into(), source })?;
        Ok(out)
    }
}

/// A reader that fails once more than `cap` bytes came through it.
struct Capped<R> {
    inner: R,
    left: u64,
    message: String,
}

impl<R: Read> Read for Capped<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if buf.is_empty() {
            return Ok(0);
        }
        let n = self.inner.read(buf)?;
        if n as u64 > self.left {
            return Err(io::Error::other(std::mem::take(&mut self.message)));
        }
        self.left -= n as u64;
        Ok(n)
    }
}

fn capped(inner: impl Read + 'static, cap: u64, message: String) -> Box<dyn Read> {
    Box::new(Capped { inner, left: cap, message })
}

/// Refuses what is not a regular file or a pipe, by its metadata, before
/// opening it; returns the file and, for a regular file, its size.
pub fn open_file(path: &Path) -> io::Result<(File, Option<u64>)> {
    let meta = std::fs::metadata(path)?;
    let kind = meta.file_type();
    if kind.is_dir() {
        return Err(io::Error::other("is a folder, not a file"));
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if kind.is_char_device() || kind.is_block_device() || kind.is_socket() {
            return Err(io::Error::other("is a device or socket, not a file"));
        }
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
        if kind.is_fifo() {
            // A FIFO with no writer would block open(2) until one comes:
            // open without waiting, then let reads wait for data as usual.
            // With no writer the first read is the end of the data, at once.
            use rustix::fs::OFlags;
            let file =
                std::fs::OpenOptions::new().read(true).custom_flags(OFlags::NONBLOCK.bits() as i32).open(path)?;
            let flags = rustix::fs::fcntl_getfl(&file)?;
            rustix::fs::fcntl_setfl(&file, flags - OFlags::NONBLOCK)?;
            return Ok((file, None));
        }
    }
    let file = File::open(path)?;
    Ok((file, kind.is_file().then_some(meta.len())))
}

fn mib(n: u64) -> String {
    if n >= 1 << 20 { format!("{} MiB", n >> 20) } else { format!("{n} bytes") }
}

/// Reads up to `n` bytes (fewer only at the end of the data).
fn read_up_to(r: &mut dyn Read, n: usize) -> io::Result<Vec<u8>> {
    let mut buf = Vec::with_capacity(n);
    r.take(n as u64).read_to_end(&mut buf)?;
    Ok(buf)
}

/// Opens `path` for reading within the [`Limits`]: refuses devices and
/// folders, decompresses gzip (and bzip2 for a `.bz2` name) within the
/// expansion bound, and checks the first bytes against `expect`.
pub(crate) fn open(path: &Path, expect: Expect) -> Result<Input, ReadError> {
    let io_err = |source| ReadError::Io { path: path.into(), source };
    let (file, size) = open_file(path).map_err(io_err)?;
    let limits = limits();
    let mut raw: Box<dyn Read> = match size {
        Some(_) => Box::new(file),
        None => {
            let cap = limits.max_stream_bytes.unwrap_or(PIPE_BYTES);
            capped(file, cap, format!("more than {} from a pipe (set FSHAPE_MAX_BYTES to read more)", mib(cap)))
        }
    };
    let head = read_up_to(&mut raw, 4).map_err(io_err)?;
    let gz = head.starts_with(&[0x1f, 0x8b]);
    let bz2 = head.starts_with(b"BZh") && path.extension().is_some_and(|e| e.eq_ignore_ascii_case("bz2"));
    let (mut rest, size_hint): (Box<dyn Read>, _) = if gz || bz2 {
        // The compressed bytes are few (bounded by the file or the pipe
        // cap): hold them, and bound what they may expand to.
        let mut compressed = head;
        raw.read_to_end(&mut compressed).map_err(io_err)?;
        let cap = limits
            .max_stream_bytes
            .unwrap_or_else(|| (EXPANSION * compressed.len() as u64).clamp(EXPANSION_FLOOR, PIPE_BYTES));
        let message = format!(
            "decompresses to more than {} ({} compressed): a damaged or hostile file? \
             (set FSHAPE_MAX_BYTES to read more)",
            mib(cap),
            mib(compressed.len() as u64)
        );
        let cursor = io::Cursor::new(compressed);
        let decoder: Box<dyn Read> = if gz {
            Box::new(flate2::read::MultiGzDecoder::new(cursor))
        } else {
            // bzip2, as nibabel reads it (`.gii.bz2`).
            Box::new(bzip2::read::MultiBzDecoder::new(cursor))
        };
        (capped(decoder, cap, message), None)
    } else {
        (Box::new(io::Cursor::new(head).chain(raw)), size)
    };
    let prefix = read_up_to(&mut rest, PREFIX).map_err(io_err)?;
    check_start(&prefix, expect).map_err(|source| ReadError::Parse { path: path.into(), source })?;
    Ok(Input { prefix, rest, size_hint })
}

/// The first bytes shown in an error: as text if printable, else in hex.
fn excerpt(b: &[u8]) -> String {
    let b = &b[..b.len().min(16)];
    if looks_like_text(b) {
        super::cursor::lossy(b.split(|&c| c == b'\n').next().unwrap_or_default())
    } else {
        b.iter().map(|c| format!("{c:02x}")).collect::<Vec<_>>().join(" ")
    }
}

/// No NUL byte: text, for the formats that are text throughout.
fn is_text(prefix: &[u8]) -> bool {
    !prefix.contains(&0)
}

/// The first 64 bytes hold no control character but tabs and line ends:
/// text, which a parser will judge and locate better than a glance at the
/// first bytes. Zeros and random bytes are not (random bytes pass with
/// probability (98/256)⁶⁴ < 10⁻²⁶).
fn looks_like_text(prefix: &[u8]) -> bool {
    prefix[..prefix.len().min(64)].iter().all(|&c| c >= 0x20 || matches!(c, b'\t' | b'\n' | b'\r'))
}

fn is_xml(prefix: &[u8]) -> bool {
    let t = prefix.strip_prefix(b"\xef\xbb\xbf").unwrap_or(prefix);
    t.trim_ascii_start().starts_with(b"<")
}

/// Refuses data whose first bytes cannot begin the expected format, and
/// are not even text a parser could locate an error in: a cheap check that
/// stops streams of zeros or random bytes early. Each format's parser
/// still checks everything.
fn check_start(prefix: &[u8], expect: Expect) -> Result<(), ParseError> {
    let sniffed = Format::sniff(prefix);
    let (ok, expected) = match expect {
        Expect::Any => (true, ""),
        Expect::Text => (is_text(prefix), "text"),
        Expect::Mesh(Format::Obj) => (is_text(prefix), "OBJ text"),
        Expect::Mesh(Format::Gifti) => (is_xml(prefix), "the start of a GIfTI file (`<?xml`)"),
        Expect::Mesh(f @ Format::Ply) => (sniffed == Some(f), "the start of a PLY file (`ply`)"),
        Expect::Mesh(f @ Format::Vtk) => (sniffed == Some(f), "the start of a VTK legacy file (`# vtk DataFile`)"),
        // Triangle (ff ff fe) and quad (ff ff ff) magics: the parser tells them.
        Expect::Mesh(Format::FreeSurfer) => {
            (prefix.starts_with(&[0xff, 0xff]), "the FreeSurfer surface magic ff ff fe")
        }
        Expect::Signal => (
            prefix.starts_with(&super::freesurfer::CURV_MAGIC)
                || prefix.starts_with(&[0, 0, 0, 1])
                || super::cifti::is_nifti2(prefix)
                || sniffed.is_some()
                || is_text(prefix),
            "a signal file (CSV text, GIfTI, FreeSurfer curv, MGH or CIFTI-2)",
        ),
    };
    if ok || prefix.is_empty() || (expect != Expect::Text && looks_like_text(prefix)) {
        return Ok(());
    }
    Err(ParseError { at: Location::Byte(0), kind: ParseErrorKind::BadToken { expected, found: excerpt(prefix) } })
}
