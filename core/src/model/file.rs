//! The crease container: one checksummed, versioned file layout shared by every model kind.
//!
//! A file is a fixed 32-byte preamble, a table of sections, and the sections. Each section is
//! named by a four-byte tag and holds raw little-endian arrays (f32/u32) or a small JSON
//! document; which sections a kind needs, and how large they must be, is the kind's business
//! (see [`crate::model::rig`]). This module only guarantees that what it hands out is exactly
//! what was written.
//!
//! # Byte layout (format version 1; integers little-endian)
//!
//! | offset      | size   | field                                                            |
//! |-------------|--------|------------------------------------------------------------------|
//! | 0           | 8      | magic `89 43 52 45 41 53 45 0A` (`\x89CREASE\n`)                  |
//! | 8           | 4      | format version, u32 (this build writes and reads 1)             |
//! | 12          | 4      | model kind, u32 (1 = rig)                                        |
//! | 16          | 4      | section count `n`, u32 (at most [`MAX_SECTIONS`])                |
//! | 20          | 4      | reserved, written 0                                              |
//! | 24          | 4      | CRC-32 of the section table (bytes `32 .. 32 + 24 n`)            |
//! | 28          | 4      | CRC-32 of the preamble (bytes `0 .. 28`)                         |
//! | 32          | 24 `n` | section table; per section: tag (4 bytes), CRC-32 of the section (u32), offset (u64), length (u64) |
//! | 32 + 24 `n` | ...    | the sections in table order, each starting at the next multiple of 8, zero bytes between |
//!
//! The file ends exactly where the last section ends. CRC-32 is the IEEE polynomial
//! (`crc32fast`, same as zlib/PNG).
//!
//! Why this shape:
//! - The magic starts with a non-ASCII byte and ends with `\n`, like PNG's, so text-mode
//!   transfers and 7-bit channels visibly damage it instead of silently passing.
//! - The preamble layout is frozen across format versions and checked first by its own CRC, so
//!   a corrupted count or version is reported as corruption, and a genuine newer file (valid
//!   CRC) as "file format version N, this build reads 1".
//! - The layout is canonical (order, alignment, zero padding, no trailing bytes): every byte of
//!   a valid file is covered by a check, so any single flipped byte is rejected.
//! - Sections start on 8-byte boundaries so a later reader may map arrays in place.
//!
//! Writing is atomic ([`write_atomic`]): the bytes go to a temporary file in the target's
//! directory, are flushed to disk, then renamed over the target, so a reader (or a crash) sees
//! the old file or the new one, never half of one.

use std::fmt;
use std::io;
use std::path::Path;

/// The eight bytes every crease file starts with.
pub const MAGIC: [u8; 8] = *b"\x89CREASE\n";

/// The container format version this build writes and the only one it reads.
pub const FORMAT_VERSION: u32 = 1;

/// Size of the fixed preamble in bytes.
pub const PREAMBLE_LEN: usize = 32;

/// Size of one section-table entry in bytes.
pub const TABLE_ENTRY_LEN: usize = 24;

/// Most sections a file may have. Generous for any model kind (a rig has 6); it bounds what a
/// corrupted or hostile count can make the reader do.
pub const MAX_SECTIONS: usize = 64;

/// Section alignment in bytes (f64/u64 arrays could be mapped in place).
pub const SECTION_ALIGN: usize = 8;

/// What a crease file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ModelKind {
    /// A skinning rig: rest mesh, proxy bones, skin weights, example bone transforms.
    Rig,
    /// A trained model: a rig plus control points, rotation regressors and the translation
    /// solver's edge weights (see [`crate::model::trained`]).
    Model,
}

impl ModelKind {
    /// The number stored in the file.
    pub fn code(self) -> u32 {
        match self {
            ModelKind::Rig => 1,
            ModelKind::Model => 2,
        }
    }

    /// The kind stored as `code`, if this build knows it.
    pub fn from_code(code: u32) -> Option<Self> {
        match code {
            1 => Some(ModelKind::Rig),
            2 => Some(ModelKind::Model),
            _ => None,
        }
    }
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModelKind::Rig => f.write_str("rig"),
            ModelKind::Model => f.write_str("trained model"),
        }
    }
}

/// A section name: four bytes, by convention upper-case ASCII (`b"META"`).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Tag(pub [u8; 4]);

impl fmt::Display for Tag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.iter().all(|b| b.is_ascii_graphic()) {
            self.0.iter().try_for_each(|&b| write!(f, "{}", b as char))
        } else {
            write!(
                f,
                "0x{:02x}{:02x}{:02x}{:02x}",
                self.0[0], self.0[1], self.0[2], self.0[3]
            )
        }
    }
}

impl fmt::Debug for Tag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Tag({self})")
    }
}

/// Everything that can be wrong with the bytes of a crease file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FormatError {
    /// The magic bytes do not match.
    #[error("not a crease file (starts with {found:02x?}, expected {MAGIC:02x?})")]
    NotCrease {
        /// The first bytes found (up to 8).
        found: Vec<u8>,
    },
    /// The file is shorter than a part it declares.
    #[error("truncated: {what} needs bytes {start}..{end}, file has {len}")]
    Truncated {
        /// The part that does not fit ("header", "section table", "section SKBW").
        what: String,
        /// First byte of the part.
        start: u64,
        /// One past its last byte.
        end: u64,
        /// File length.
        len: u64,
    },
    /// A stored checksum does not match the bytes.
    #[error("checksum mismatch in {what}: stored {stored:08x}, computed {computed:08x}")]
    Checksum {
        /// "header", "section table" or "section XFRM".
        what: String,
        /// The CRC-32 in the file.
        stored: u32,
        /// The CRC-32 of the bytes read.
        computed: u32,
    },
    /// The file was written by a different format version.
    #[error("file format version {found}, this build reads {FORMAT_VERSION}")]
    UnsupportedVersion {
        /// The version in the file.
        found: u32,
    },
    /// The kind number is not one this build knows.
    #[error("unknown model kind {code} (this build knows 1 = rig)")]
    UnknownKind {
        /// The number in the file.
        code: u32,
    },
    /// The file holds a different kind of model than the caller asked for.
    #[error("expected a {expected} file, found a {found} file")]
    WrongKind {
        /// What the caller wanted.
        expected: ModelKind,
        /// What the file holds.
        found: ModelKind,
    },
    /// The header, table or padding breaks the layout rules.
    #[error("bad layout: {0}")]
    Layout(String),
    /// A section the model kind needs is absent.
    #[error("missing section {tag}")]
    MissingSection {
        /// The absent tag.
        tag: Tag,
    },
    /// A section's size disagrees with the metadata.
    #[error("section {tag} is {got} bytes, expected {expected} ({what})")]
    SectionSize {
        /// The section.
        tag: Tag,
        /// Its length.
        got: u64,
        /// The length the metadata implies.
        expected: u64,
        /// How the expectation was computed ("f32 x 3 x 8431 vertices").
        what: String,
    },
    /// A JSON section does not parse or is not what the kind expects.
    #[error("section {tag}: {source}")]
    Json {
        /// The section.
        tag: Tag,
        /// The parser's complaint.
        #[source]
        source: serde_json::Error,
    },
    /// Metadata values that are individually well-formed but cannot describe a real file.
    #[error("section {tag}: {detail}")]
    Metadata {
        /// The section.
        tag: Tag,
        /// What is wrong.
        detail: String,
    },
}

/// One entry of the section table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SectionEntry {
    /// The section's tag.
    pub tag: Tag,
    /// Byte offset of the section in the file.
    pub offset: u64,
    /// Length of the section in bytes.
    pub len: u64,
    /// CRC-32 of the section's bytes.
    pub crc: u32,
}

/// Builds a container in memory. Sections are written in the order they are added.
#[derive(Debug)]
pub struct ContainerWriter {
    kind: ModelKind,
    sections: Vec<(Tag, Vec<u8>)>,
}

impl ContainerWriter {
    /// An empty container of the given kind.
    pub fn new(kind: ModelKind) -> Self {
        Self {
            kind,
            sections: Vec::new(),
        }
    }

    /// Adds a section of raw bytes.
    ///
    /// # Panics
    /// If `tag` was already added or more than [`MAX_SECTIONS`] are added: both are bugs in
    /// the model kind's writer, not conditions of the data.
    pub fn add(&mut self, tag: Tag, bytes: Vec<u8>) {
        assert!(
            self.sections.iter().all(|(t, _)| *t != tag),
            "section {tag} added twice"
        );
        assert!(
            self.sections.len() < MAX_SECTIONS,
            "more than {MAX_SECTIONS} sections"
        );
        self.sections.push((tag, bytes));
    }

    /// Adds a section of little-endian f32 values.
    pub fn add_f32s(&mut self, tag: Tag, values: &[f32]) {
        self.add(tag, values.iter().flat_map(|v| v.to_le_bytes()).collect());
    }

    /// Adds a section of little-endian u32 values.
    pub fn add_u32s(&mut self, tag: Tag, values: &[u32]) {
        self.add(tag, values.iter().flat_map(|v| v.to_le_bytes()).collect());
    }

    /// Adds a section holding `value` as JSON.
    pub fn add_json<T: serde::Serialize>(
        &mut self,
        tag: Tag,
        value: &T,
    ) -> Result<(), FormatError> {
        let bytes =
            serde_json::to_vec(value).map_err(|source| FormatError::Json { tag, source })?;
        self.add(tag, bytes);
        Ok(())
    }

    /// The complete file.
    pub fn to_bytes(&self) -> Vec<u8> {
        let n = self.sections.len();
        let table_end = PREAMBLE_LEN + n * TABLE_ENTRY_LEN;
        let mut table = Vec::with_capacity(n * TABLE_ENTRY_LEN);
        let mut offset = table_end;
        for (tag, bytes) in &self.sections {
            offset = offset.next_multiple_of(SECTION_ALIGN);
            table.extend_from_slice(&tag.0);
            table.extend_from_slice(&crc32fast::hash(bytes).to_le_bytes());
            table.extend_from_slice(&(offset as u64).to_le_bytes());
            table.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
            offset += bytes.len();
        }
        let mut out = Vec::with_capacity(offset);
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&self.kind.code().to_le_bytes());
        out.extend_from_slice(&(n as u32).to_le_bytes());
        out.extend_from_slice(&0u32.to_le_bytes());
        out.extend_from_slice(&crc32fast::hash(&table).to_le_bytes());
        let preamble_crc = crc32fast::hash(&out);
        out.extend_from_slice(&preamble_crc.to_le_bytes());
        out.extend_from_slice(&table);
        for (_, bytes) in &self.sections {
            out.resize(out.len().next_multiple_of(SECTION_ALIGN), 0);
            out.extend_from_slice(bytes);
        }
        debug_assert_eq!(out.len(), offset);
        out
    }
}

/// A parsed, fully verified container borrowing the file's bytes.
#[derive(Debug)]
pub struct Container<'a> {
    bytes: &'a [u8],
    version: u32,
    kind: ModelKind,
    entries: Vec<SectionEntry>,
}

/// Reads a little-endian u32 at `at`; the caller has checked `at + 4 <= bytes.len()`.
fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

/// Reads a little-endian u64 at `at`; the caller has checked `at + 8 <= bytes.len()`.
fn u64_at(bytes: &[u8], at: usize) -> u64 {
    (u32_at(bytes, at) as u64) | ((u32_at(bytes, at + 4) as u64) << 32)
}

impl<'a> Container<'a> {
    /// Parses and verifies a whole file: magic, preamble checksum, version, kind, table
    /// checksum, layout, and every section's checksum. Never panics on any input.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, FormatError> {
        let len = bytes.len() as u64;
        if bytes.len() < MAGIC.len() || bytes[..MAGIC.len()] != MAGIC {
            if MAGIC.starts_with(bytes) {
                // A prefix of the magic: a crease file cut short, not a foreign file.
                return Err(truncated("header", 0, PREAMBLE_LEN as u64, len));
            }
            return Err(FormatError::NotCrease {
                found: bytes[..bytes.len().min(8)].to_vec(),
            });
        }
        if bytes.len() < PREAMBLE_LEN {
            return Err(truncated("header", 0, PREAMBLE_LEN as u64, len));
        }
        let stored = u32_at(bytes, 28);
        let computed = crc32fast::hash(&bytes[..28]);
        if stored != computed {
            return Err(FormatError::Checksum {
                what: "header".into(),
                stored,
                computed,
            });
        }
        let version = u32_at(bytes, 8);
        if version != FORMAT_VERSION {
            return Err(FormatError::UnsupportedVersion { found: version });
        }
        let code = u32_at(bytes, 12);
        let kind = ModelKind::from_code(code).ok_or(FormatError::UnknownKind { code })?;
        let n = u32_at(bytes, 16) as usize;
        if n > MAX_SECTIONS {
            return Err(FormatError::Layout(format!(
                "{n} sections, at most {MAX_SECTIONS} allowed"
            )));
        }
        let reserved = u32_at(bytes, 20);
        if reserved != 0 {
            return Err(FormatError::Layout(format!(
                "reserved header field is {reserved}, not 0"
            )));
        }
        let table_end = PREAMBLE_LEN + n * TABLE_ENTRY_LEN;
        if bytes.len() < table_end {
            return Err(truncated(
                "section table",
                PREAMBLE_LEN as u64,
                table_end as u64,
                len,
            ));
        }
        let stored = u32_at(bytes, 24);
        let computed = crc32fast::hash(&bytes[PREAMBLE_LEN..table_end]);
        if stored != computed {
            return Err(FormatError::Checksum {
                what: "section table".into(),
                stored,
                computed,
            });
        }

        let mut entries: Vec<SectionEntry> = Vec::with_capacity(n);
        let mut expected_offset = table_end as u64;
        for i in 0..n {
            let at = PREAMBLE_LEN + i * TABLE_ENTRY_LEN;
            let tag = Tag([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
            let entry = SectionEntry {
                tag,
                crc: u32_at(bytes, at + 4),
                offset: u64_at(bytes, at + 8),
                len: u64_at(bytes, at + 16),
            };
            if entries.iter().any(|e| e.tag == tag) {
                return Err(FormatError::Layout(format!("section {tag} appears twice")));
            }
            let padding_start = expected_offset;
            expected_offset = expected_offset.next_multiple_of(SECTION_ALIGN as u64);
            if entry.offset != expected_offset {
                return Err(FormatError::Layout(format!(
                    "section {tag} starts at byte {}, expected {expected_offset}",
                    entry.offset
                )));
            }
            let end = entry.offset.checked_add(entry.len).ok_or_else(|| {
                FormatError::Layout(format!("section {tag} length {} overflows", entry.len))
            })?;
            if end > len {
                return Err(truncated(&format!("section {tag}"), entry.offset, end, len));
            }
            // Both bounds are <= len, so they fit in usize.
            let (start, end_us) = (entry.offset as usize, end as usize);
            if bytes[padding_start as usize..start].iter().any(|&b| b != 0) {
                return Err(FormatError::Layout(format!(
                    "non-zero padding before section {tag} (bytes {padding_start}..{start})"
                )));
            }
            let computed = crc32fast::hash(&bytes[start..end_us]);
            if computed != entry.crc {
                return Err(FormatError::Checksum {
                    what: format!("section {tag}"),
                    stored: entry.crc,
                    computed,
                });
            }
            expected_offset = end;
            entries.push(entry);
        }
        if len != expected_offset {
            return Err(FormatError::Layout(format!(
                "{} bytes after the last section (file is {len} bytes, sections end at \
                 {expected_offset})",
                len - expected_offset
            )));
        }
        Ok(Self {
            bytes,
            version,
            kind,
            entries,
        })
    }

    /// The format version (always [`FORMAT_VERSION`] for a parsed file).
    pub fn version(&self) -> u32 {
        self.version
    }

    /// The model kind.
    pub fn kind(&self) -> ModelKind {
        self.kind
    }

    /// Errors unless the file holds `expected`.
    pub fn expect_kind(&self, expected: ModelKind) -> Result<(), FormatError> {
        if self.kind == expected {
            Ok(())
        } else {
            Err(FormatError::WrongKind {
                expected,
                found: self.kind,
            })
        }
    }

    /// The section table, in file order.
    pub fn entries(&self) -> &[SectionEntry] {
        &self.entries
    }

    /// The bytes of section `tag`, if present.
    pub fn section(&self, tag: Tag) -> Option<&'a [u8]> {
        let e = self.entries.iter().find(|e| e.tag == tag)?;
        // Verified in parse: offset + len <= bytes.len().
        Some(&self.bytes[e.offset as usize..(e.offset + e.len) as usize])
    }

    /// The bytes of section `tag`, or [`FormatError::MissingSection`].
    pub fn require(&self, tag: Tag) -> Result<&'a [u8], FormatError> {
        self.section(tag).ok_or(FormatError::MissingSection { tag })
    }

    /// Section `tag` as JSON.
    pub fn json<T: serde::de::DeserializeOwned>(&self, tag: Tag) -> Result<T, FormatError> {
        serde_json::from_slice(self.require(tag)?)
            .map_err(|source| FormatError::Json { tag, source })
    }

    /// Section `tag` as exactly `count` little-endian f32 values; `what` explains the count in
    /// the error ("3 x 8431 vertices").
    pub fn f32s(&self, tag: Tag, count: usize, what: &str) -> Result<Vec<f32>, FormatError> {
        let b = self.sized(tag, count, "f32", what)?;
        Ok(b.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }

    /// Section `tag` as exactly `count` little-endian u32 values.
    pub fn u32s(&self, tag: Tag, count: usize, what: &str) -> Result<Vec<u32>, FormatError> {
        let b = self.sized(tag, count, "u32", what)?;
        Ok(b.chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }

    /// Section `tag`, checked to hold `count` 4-byte values.
    fn sized(&self, tag: Tag, count: usize, ty: &str, what: &str) -> Result<&'a [u8], FormatError> {
        let b = self.require(tag)?;
        let expected = (count as u64).saturating_mul(4);
        if b.len() as u64 != expected {
            return Err(FormatError::SectionSize {
                tag,
                got: b.len() as u64,
                expected,
                what: format!("{ty} x {what}"),
            });
        }
        Ok(b)
    }
}

/// A [`FormatError::Truncated`].
fn truncated(what: &str, start: u64, end: u64, len: u64) -> FormatError {
    FormatError::Truncated {
        what: what.to_string(),
        start,
        end,
        len,
    }
}

/// Writes `bytes` to `path` atomically: a temporary file beside it, fsync, rename, then the
/// directory fsync (best effort); on error `path` is left as it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    crate::atomic::write_atomic_with(path, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<u8> {
        let mut w = ContainerWriter::new(ModelKind::Rig);
        w.add(Tag(*b"AAAA"), vec![1, 2, 3]);
        w.add_f32s(Tag(*b"BBBB"), &[1.5, -2.0]);
        w.add(Tag(*b"EMPT"), vec![]);
        w.add_u32s(Tag(*b"CCCC"), &[7]);
        w.to_bytes()
    }

    #[test]
    fn round_trip_and_layout() {
        let bytes = sample();
        let c = Container::parse(&bytes).unwrap();
        assert_eq!(c.kind(), ModelKind::Rig);
        assert_eq!(c.section(Tag(*b"AAAA")), Some(&[1u8, 2, 3][..]));
        assert_eq!(c.f32s(Tag(*b"BBBB"), 2, "test").unwrap(), vec![1.5, -2.0]);
        assert_eq!(c.u32s(Tag(*b"CCCC"), 1, "test").unwrap(), vec![7]);
        assert_eq!(c.section(Tag(*b"EMPT")), Some(&[][..]));
        assert!(c.entries().iter().all(|e| e.offset % 8 == 0));
        assert!(matches!(
            c.require(Tag(*b"ZZZZ")),
            Err(FormatError::MissingSection { .. })
        ));
        assert!(matches!(
            c.f32s(Tag(*b"BBBB"), 3, "x"),
            Err(FormatError::SectionSize { .. })
        ));
    }

    #[test]
    fn every_single_byte_flip_is_rejected() {
        let bytes = sample();
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x10;
            assert!(Container::parse(&b).is_err(), "flip at byte {i} accepted");
        }
    }

    #[test]
    fn every_truncation_is_rejected_without_panic() {
        let bytes = sample();
        for len in 0..bytes.len() {
            let e = Container::parse(&bytes[..len]).unwrap_err();
            assert!(matches!(e, FormatError::Truncated { .. }), "len {len}: {e}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(matches!(
            Container::parse(&longer),
            Err(FormatError::Layout(_))
        ));
    }

    #[test]
    fn foreign_files() {
        let e = Container::parse(b"glTF\x02\0\0\0....").unwrap_err();
        assert!(e.to_string().starts_with("not a crease file"), "{e}");
        assert!(Container::parse(b"").is_err());
    }
}
