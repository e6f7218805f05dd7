//! A streaming reader of MCAP files (<https://mcap.dev/spec>) for what a background needs: the
//! schemas, channels and messages of the data section, in file order, inside chunks or not.
//!
//! pedscan writes MCAP with the `mcap` crate, but reads it here: its reader panics on some
//! malformed records (an attachment shorter than its header; an uncompressed chunk whose
//! record overruns it), and every byte of a user's file must give an answer or a named error.
//! Each record is at most [`RECORD_LIMIT`] bytes (a chunk's uncompressed records too), read
//! one at a time; a chunk is `""` (plain) or `"zstd"`, its CRC checked when it has one. The
//! summary section is not needed and not read. A file that ends at a record boundary before
//! its data end (a recorder stopped without closing it) is read up to there; one that ends
//! inside a record is an error.

use std::collections::HashMap;
use std::io::Read;

/// The longest record (and uncompressed chunk) read, bytes.
pub const RECORD_LIMIT: usize = 256 << 20;

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// A channel: its topic, message encoding and schema name.
#[derive(Clone, Debug, Default)]
pub struct Channel {
    pub topic: String,
    pub message_encoding: String,
    pub schema: String,
}

/// Why a file cannot be read, and where: the byte offset of the record (in the file, or of
/// the chunk holding it).
#[derive(Debug)]
pub struct Bad {
    pub at: u64,
    pub why: String,
}

/// Reads the messages of an MCAP stream.
pub struct Reader<R> {
    src: R,
    /// Bytes read so far, and the source's length when known.
    pos: u64,
    len: Option<u64>,
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, Channel>,
    body: Vec<u8>,
    /// Messages of the chunk being read, in order, with their channel ids.
    pending: std::collections::VecDeque<(u16, Vec<u8>)>,
    done: bool,
    /// True when the file ended at a record boundary before its data end.
    pub cut_short: bool,
}

/// Little-endian fields of a record body, bounds-checked.
struct Body<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Body<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        match self.at.checked_add(n).filter(|&e| e <= self.b.len()) {
            Some(end) => {
                let s = &self.b[self.at..end];
                self.at = end;
                Ok(s)
            }
            None => Err(format!("{what} runs past the end of its record ({} bytes)", self.b.len())),
        }
    }
    fn u16(&mut self, what: &str) -> Result<u16, String> {
        Ok(u16::from_le_bytes(self.take(2, what)?.try_into().expect("2 bytes")))
    }
    fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self, what: &str) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }
    fn string(&mut self, what: &str) -> Result<String, String> {
        let n = self.u32(what)? as usize;
        let s = self.take(n, what)?;
        String::from_utf8(s.to_vec()).map_err(|_| format!("{what} is not UTF-8"))
    }
    fn rest(&self) -> &'a [u8] {
        &self.b[self.at..]
    }
}

impl<R: Read> Reader<R> {
    /// Starts reading `src` (`len` bytes long, when known), which must begin with the MCAP magic.
    pub fn new(src: R, len: Option<u64>) -> Result<Reader<R>, Bad> {
        let mut r = Reader {
            src,
            pos: 0,
            len,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            body: Vec::new(),
            pending: Default::default(),
            done: false,
            cut_short: false,
        };
        let mut magic = [0u8; 8];
        if r.fill(&mut magic)? < 8 || &magic != MAGIC {
            return Err(Bad { at: 0, why: "does not start with the MCAP magic (not an MCAP file)".into() });
        }
        Ok(r)
    }

    /// Fills `buf` from the source; the bytes read (fewer only at the end).
    fn fill(&mut self, buf: &mut [u8]) -> Result<usize, Bad> {
        let mut got = 0;
        while got < buf.len() {
            match self.src.read(&mut buf[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Bad { at: self.pos, why: format!("cannot read: {e}") }),
            }
        }
        self.pos += got as u64;
        Ok(got)
    }

    /// The next message: its channel and data. `None` at the data section's end.
    pub fn next_message(&mut self) -> Result<Option<(Channel, Vec<u8>)>, Bad> {
        loop {
            if let Some((id, data)) = self.pending.pop_front() {
                return Ok(Some((self.channel(id, self.pos)?, data)));
            }
            if self.done {
                return Ok(None);
            }
            let at = self.pos;
            let mut head = [0u8; 9];
            let got = self.fill(&mut head)?;
            if got == 0 {
                self.cut_short = true;
                self.done = true;
                return Ok(None);
            }
            if got < 9 {
                return Err(Bad { at, why: "the file ends inside a record's opcode and length (cut short?)".into() });
            }
            let op = head[0];
            let len = u64::from_le_bytes(head[1..].try_into().expect("8 bytes"));
            if len > RECORD_LIMIT as u64 {
                return Err(Bad { at, why: format!("record 0x{op:02x} claims {len} bytes, more than the {RECORD_LIMIT} read") });
            }
            if let Some(total) = self.len.filter(|&t| self.pos + len > t) {
                return Err(Bad { at, why: format!("record 0x{op:02x} claims {len} bytes, the file ends after {} (cut short?)", total - self.pos) });
            }
            let mut body = std::mem::take(&mut self.body);
            body.resize(len as usize, 0);
            let got = self.fill(&mut body)?;
            if got < body.len() {
                return Err(Bad { at, why: format!("record 0x{op:02x} claims {len} bytes, the file ends after {got} (cut short?)") });
            }
            let r = match op {
                // Footer, data end: the data section is over.
                0x02 | 0x0F => {
                    self.done = true;
                    Ok(())
                }
                0x06 => self.chunk(&body, at),
                _ => match self.record(op, &body, at, false) {
                    Ok(Some(m)) => {
                        self.body = body;
                        return Ok(Some(m));
                    }
                    Ok(None) => Ok(()),
                    Err(e) => Err(e),
                },
            };
            self.body = body;
            r?;
        }
    }

    fn channel(&self, id: u16, at: u64) -> Result<Channel, Bad> {
        self.channels.get(&id).cloned().ok_or_else(|| Bad { at, why: format!("a message on channel {id}, which no channel record defined") })
    }

    /// A schema, channel or message record (others are skipped); a message outside a chunk is
    /// returned, one inside (`in_chunk`) queued.
    fn record(&mut self, op: u8, body: &[u8], at: u64, in_chunk: bool) -> Result<Option<(Channel, Vec<u8>)>, Bad> {
        let bad = |why: String| Bad { at, why: format!("record 0x{op:02x}: {why}") };
        let mut b = Body { b: body, at: 0 };
        match op {
            0x03 => {
                let id = b.u16("schema id").map_err(bad)?;
                let name = b.string("schema name").map_err(bad)?;
                self.schemas.insert(id, name);
            }
            0x04 => {
                let id = b.u16("channel id").map_err(bad)?;
                let schema_id = b.u16("channel schema id").map_err(bad)?;
                let topic = b.string("channel topic").map_err(bad)?;
                let message_encoding = b.string("channel message encoding").map_err(bad)?;
                let schema = match schema_id {
                    0 => String::new(),
                    s => self.schemas.get(&s).cloned().ok_or_else(|| bad(format!("channel '{topic}' names schema {s}, which no schema record defined")))?,
                };
                self.channels.insert(id, Channel { topic, message_encoding, schema });
            }
            0x05 => {
                let id = b.u16("message channel id").map_err(bad)?;
                b.take(4 + 8 + 8, "message sequence and times").map_err(bad)?;
                let data = b.rest().to_vec();
                if in_chunk {
                    self.pending.push_back((id, data));
                } else {
                    return Ok(Some((self.channel(id, at)?, data)));
                }
            }
            _ => {}
        }
        Ok(None)
    }

    /// A chunk: its records, decompressed and checked, read in order.
    fn chunk(&mut self, body: &[u8], at: u64) -> Result<(), Bad> {
        let bad = |why: String| Bad { at, why: format!("chunk: {why}") };
        let mut b = Body { b: body, at: 0 };
        b.take(16, "message times").map_err(bad)?;
        let size = b.u64("uncompressed size").map_err(bad)?;
        let crc = b.u32("uncompressed CRC").map_err(bad)?;
        let compression = b.string("compression").map_err(bad)?;
        let n = b.u64("records length").map_err(bad)?;
        let records = b.take(usize::try_from(n).unwrap_or(usize::MAX), "records").map_err(bad)?;
        if size > RECORD_LIMIT as u64 {
            return Err(bad(format!("{size} bytes uncompressed, more than the {RECORD_LIMIT} read")));
        }
        let plain: std::borrow::Cow<[u8]> = match compression.as_str() {
            "" => records.into(),
            "zstd" => zstd::bulk::decompress(records, size as usize).map_err(|e| bad(format!("zstd: {e}")))?.into(),
            other => return Err(bad(format!("compressed with '{other}'; pedscan reads plain and zstd chunks (mcap recompress --compression zstd)"))),
        };
        if plain.len() as u64 != size {
            return Err(bad(format!("{} bytes of records where its header says {size}", plain.len())));
        }
        if crc != 0 && crc32fast::hash(&plain) != crc {
            return Err(bad("its records do not match their CRC (a damaged file)".into()));
        }
        let mut r = Body { b: &plain, at: 0 };
        while r.at < plain.len() {
            let op = r.take(1, "inner record opcode").map_err(bad)?[0];
            let len = r.u64("inner record length").map_err(bad)?;
            let inner = r.take(usize::try_from(len).unwrap_or(usize::MAX), "inner record").map_err(bad)?;
            self.record(op, inner, at, true)?;
        }
        Ok(())
    }
}
