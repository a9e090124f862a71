//! NumPy `.npz` archives: a zip of `.npy` arrays, as `np.savez` writes
//! them and `np.load` reads them.
//!
//! Written: uncompressed (stored) entries with their CRC-32, the layout
//! `np.savez` itself uses. Read: stored entries, with zip64 sizes where
//! NumPy writes them; every entry's CRC-32 is checked, so a truncated or
//! damaged archive is an error, never a silently wrong array. Compressed
//! archives (`np.savez_compressed`) are refused with a message saying so.
//! See PKWARE's APPNOTE (sections 4.3.7, 4.3.12, 4.3.16 and 4.5.3) for the
//! records.

use std::io::{self, Write};

const LOCAL: u32 = 0x0403_4b50;
const CENTRAL: u32 = 0x0201_4b50;
const END: u32 = 0x0605_4b50;
/// 1980-01-01 00:00 in DOS time and date: archives are reproducible.
const DOS_TIME: u16 = 0;
const DOS_DATE: u16 = (1 << 5) | 1;

/// The CRC-32 of `data` (the zip and PNG polynomial, reflected,
/// 0xEDB88320).
pub fn crc32(data: &[u8]) -> u32 {
    static TABLE: std::sync::OnceLock<[u32; 256]> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut t = [0u32; 256];
        for (i, e) in t.iter_mut().enumerate() {
            let mut c = i as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xedb8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
            *e = c;
        }
        t
    });
    !data.iter().fold(!0u32, |c, &b| {
        table[((c ^ u32::from(b)) & 0xff) as usize] ^ (c >> 8)
    })
}

/// Writes an archive of `(name, bytes)` entries, each stored as it is
/// (names end in `.npy` for `np.load` to give them as arrays, without the
/// suffix). Entries and the whole archive must stay below 4 GiB.
pub fn write_archive<W: Write + ?Sized>(w: &mut W, entries: &[(&str, &[u8])]) -> io::Result<()> {
    let too_big = || io::Error::new(io::ErrorKind::InvalidInput, "npz: archive over 4 GiB");
    let mut central = Vec::new();
    let mut offset = 0u64;
    for (name, data) in entries {
        let size = u32::try_from(data.len()).map_err(|_| too_big())?;
        let name_len = u16::try_from(name.len()).map_err(|_| too_big())?;
        let crc = crc32(data);
        let at = u32::try_from(offset).map_err(|_| too_big())?;
        let mut local = Vec::with_capacity(30 + name.len());
        local.extend_from_slice(&LOCAL.to_le_bytes());
        for v in [20u16, 0, 0, DOS_TIME, DOS_DATE] {
            local.extend_from_slice(&v.to_le_bytes());
        }
        for v in [crc, size, size] {
            local.extend_from_slice(&v.to_le_bytes());
        }
        local.extend_from_slice(&name_len.to_le_bytes());
        local.extend_from_slice(&0u16.to_le_bytes());
        local.extend_from_slice(name.as_bytes());
        w.write_all(&local)?;
        w.write_all(data)?;
        offset += (local.len() + data.len()) as u64;

        central.extend_from_slice(&CENTRAL.to_le_bytes());
        for v in [20u16, 20, 0, 0, DOS_TIME, DOS_DATE] {
            central.extend_from_slice(&v.to_le_bytes());
        }
        for v in [crc, size, size] {
            central.extend_from_slice(&v.to_le_bytes());
        }
        for v in [name_len, 0, 0, 0, 0] {
            central.extend_from_slice(&v.to_le_bytes());
        }
        central.extend_from_slice(&0u32.to_le_bytes());
        central.extend_from_slice(&at.to_le_bytes());
        central.extend_from_slice(name.as_bytes());
    }
    let count = u16::try_from(entries.len()).map_err(|_| too_big())?;
    let cd_size = u32::try_from(central.len()).map_err(|_| too_big())?;
    let cd_at = u32::try_from(offset).map_err(|_| too_big())?;
    w.write_all(&central)?;
    let mut end = Vec::with_capacity(22);
    end.extend_from_slice(&END.to_le_bytes());
    for v in [0u16, 0, count, count] {
        end.extend_from_slice(&v.to_le_bytes());
    }
    end.extend_from_slice(&cd_size.to_le_bytes());
    end.extend_from_slice(&cd_at.to_le_bytes());
    end.extend_from_slice(&0u16.to_le_bytes());
    w.write_all(&end)
}

/// One entry of an archive read by [`read_archive`]: its name and bytes
/// (borrowed from the archive).
#[derive(Debug, Clone, PartialEq)]
pub struct Entry<'a> {
    /// The name stored in the archive (`eigenvalues.npy`, ...).
    pub name: String,
    /// The entry's content, checked against its CRC-32.
    pub data: &'a [u8],
}

/// The entries of a stored (uncompressed) zip archive, in the order of its
/// central directory. The error gives the byte offset and what is wrong.
pub fn read_archive(bytes: &[u8]) -> Result<Vec<Entry<'_>>, (usize, String)> {
    let u16_at = |at: usize| -> Result<u16, (usize, String)> {
        bytes
            .get(at..at + 2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .ok_or((at, "the archive ends inside a record".into()))
    };
    let u32_at = |at: usize| -> Result<u32, (usize, String)> {
        bytes
            .get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .ok_or((at, "the archive ends inside a record".into()))
    };
    // The end record is within the last 22 + 65535 bytes (its comment).
    let lowest = bytes.len().saturating_sub(22 + 0xffff);
    let end = (lowest..=bytes.len().saturating_sub(22))
        .rev()
        .find(|&i| bytes.len() >= 22 && u32_at(i).is_ok_and(|s| s == END))
        .ok_or((
            bytes.len(),
            "not a zip archive (no end-of-central-directory record)".to_string(),
        ))?;
    let count = usize::from(u16_at(end + 10)?);
    let mut at = u32_at(end + 16)? as usize;
    let mut entries = Vec::with_capacity(count.min(bytes.len() / 46));
    for _ in 0..count {
        if u32_at(at)? != CENTRAL {
            return Err((at, "a central directory record was expected".into()));
        }
        let method = u16_at(at + 10)?;
        let crc = u32_at(at + 16)?;
        let mut csize = u64::from(u32_at(at + 20)?);
        let mut usize_ = u64::from(u32_at(at + 24)?);
        let name_len = usize::from(u16_at(at + 28)?);
        let extra_len = usize::from(u16_at(at + 30)?);
        let comment_len = usize::from(u16_at(at + 32)?);
        let mut offset = u64::from(u32_at(at + 42)?);
        let name_at = at + 46;
        let name = bytes
            .get(name_at..name_at + name_len)
            .ok_or((name_at, "the archive ends inside a name".to_string()))?;
        let name = String::from_utf8_lossy(name).into_owned();
        // Zip64: the sizes and offset that do not fit are in extra field 1,
        // in this order, only those marked 0xFFFFFFFF.
        let mut extra = name_at + name_len;
        let extra_end = extra + extra_len;
        while extra + 4 <= extra_end {
            let (id, len) = (u16_at(extra)?, usize::from(u16_at(extra + 2)?));
            if id == 1 {
                let mut p = extra + 4;
                for field in [&mut usize_, &mut csize, &mut offset] {
                    if *field == u64::from(u32::MAX) && p + 8 <= extra + 4 + len {
                        *field = u64::from(u32_at(p)?) | (u64::from(u32_at(p + 4)?) << 32);
                        p += 8;
                    }
                }
            }
            extra += 4 + len;
        }
        if method != 0 {
            return Err((
                at,
                format!(
                    "{name}: compressed (method {method}); only stored entries are read \
                     (write with np.savez, not np.savez_compressed)"
                ),
            ));
        }
        if csize != usize_ {
            return Err((at, format!("{name}: stored sizes differ")));
        }
        let local = usize::try_from(offset).map_err(|_| (at, "offset too large".to_string()))?;
        if u32_at(local)? != LOCAL {
            return Err((local, format!("{name}: no local header at its offset")));
        }
        let start =
            local + 30 + usize::from(u16_at(local + 26)?) + usize::from(u16_at(local + 28)?);
        let data = usize::try_from(csize)
            .ok()
            .and_then(|n| start.checked_add(n))
            .and_then(|e| bytes.get(start..e))
            .ok_or((start, format!("{name}: the archive ends inside its data")))?;
        if crc32(data) != crc {
            return Err((start, format!("{name}: CRC-32 mismatch (damaged data)")));
        }
        entries.push(Entry { name, data });
        at = name_at + name_len + extra_len + comment_len;
    }
    Ok(entries)
}

/// Reads the archive file `path` (at most `limit` bytes) and parses it with
/// `parse`; its errors (a byte offset where known, and what is wrong)
/// become parse errors of `format` naming the file.
pub(crate) fn read_file<T>(
    path: &std::path::Path,
    limit: u64,
    format: &'static str,
    parse: impl FnOnce(&[u8]) -> Result<T, (Option<usize>, String)>,
) -> crate::Result<T> {
    let data = crate::read_bounded(path, limit)?;
    parse(&data).map_err(|(at, message)| crate::Error::Parse {
        path: Some(path.to_path_buf()),
        format,
        location: at.map_or(crate::Location::End, crate::Location::Byte),
        message,
    })
}

/// The content of the entry `name.npy` of `entries`; missing, an error
/// saying the archive is not a `what`.
pub(crate) fn entry<'a>(
    entries: &[Entry<'a>],
    name: &str,
    what: &str,
) -> Result<&'a [u8], (Option<usize>, String)> {
    entries
        .iter()
        .find(|e| e.name == format!("{name}.npy"))
        .map(|e| e.data)
        .ok_or((None, format!("no `{name}` entry: not an fmaps {what}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_of_the_check_string() {
        // The standard check value of CRC-32 (ISO-HDLC).
        assert_eq!(crc32(b"123456789"), 0xcbf4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn an_archive_round_trips_and_damage_is_caught() {
        let a: Vec<u8> = (0..200u8).collect();
        let mut z = Vec::new();
        write_archive(
            &mut z,
            &[("a.npy", &a), ("empty.npy", &[]), ("b.npy", b"xyz")],
        )
        .unwrap();
        let e = read_archive(&z).unwrap();
        let names: Vec<&str> = e.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["a.npy", "empty.npy", "b.npy"]);
        assert_eq!(e[0].data, &a[..]);
        assert_eq!(e[2].data, b"xyz");
        // Every truncation and every flipped byte of the data: an error
        // (or, for bytes no check covers, the same entries), never a panic.
        for cut in 0..z.len() {
            assert!(read_archive(&z[..cut]).is_err(), "cut at {cut}");
        }
        for i in 0..z.len() {
            let mut d = z.clone();
            d[i] ^= 0x5a;
            if let Ok(e2) = read_archive(&d) {
                // Only the unchecked fields (times, versions, attributes)
                // may change without an error; the content never does.
                assert_eq!(e2.len(), 3, "byte {i}");
                assert_eq!(e2[0].data, &a[..], "byte {i}");
                assert_eq!(e2[2].data, b"xyz", "byte {i}");
            }
        }
    }
}
