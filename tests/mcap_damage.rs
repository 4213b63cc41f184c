//! Damaged MCAP recordings (issue 28: R1–R4): `jderobot info`, the replay's load
//! (also what `check` of a replay conf runs) and the replay's message loop read
//! every damaged copy without a panic, without an allocation over a stated bound,
//! and say what is damaged and where; damage never changes a message silently.
//!
//! The recordings are `assets/recordings/simple.mcap` written again as the
//! recorder writes (`mcapfmt::write_options`, `add_channel`; a chunk closed every
//! 25 messages, as the recorder's one-second flush does) in zstd, lz4 and
//! uncompressed forms. The whole binary runs under a counting allocator: no single
//! allocation may exceed [`MAX_ALLOC`].
#![cfg(all(feature = "replay", feature = "recorder"))]

use std::{
    alloc::{GlobalAlloc, Layout, System},
    cell::Cell,
    collections::{BTreeMap, HashSet},
    io::Cursor,
    ops::ControlFlow,
    path::{Path, PathBuf},
    process::{Command, Stdio},
    sync::Arc,
    time::Instant,
};

use crate::common;

use jderobot::{
    interfaces::{Image, Sample},
    mcapfmt::{self, Profile, Recorded, Snapshot, Summary, reader},
};

const BIN: &str = env!("CARGO_BIN_EXE_jderobot");

/// The largest single allocation allowed while reading the test recordings
/// (each under 1 MB; their chunks decompress to under 1 MB).
const MAX_ALLOC: usize = 4 << 20;

struct Counting;
thread_local! {
    /// Whether this thread's allocations are measured ([`measure_allocations`]):
    /// only a test's own thread, so another test of the binary that allocates a
    /// large buffer at the same time (a recorder's frames, a child's output) is
    /// not counted against this one.
    static MEASURED: Cell<bool> = const { Cell::new(false) };
    /// The largest allocation this thread asked for while measured.
    static LARGEST: Cell<usize> = const { Cell::new(0) };
}

/// Notes an allocation of `size` bytes when this thread is measured.
fn note(size: usize) {
    let _ = MEASURED.try_with(|m| {
        if m.get() {
            let _ = LARGEST.try_with(|l| l.set(l.get().max(size)));
        }
    });
}

/// Measures this thread's allocations from now on (for [`assert_alloc_bound`]).
fn measure_allocations() {
    MEASURED.with(|m| m.set(true));
}

// SAFETY: forwards to the system allocator, only noting the sizes asked for.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        note(l.size());
        unsafe { System.alloc(l) }
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        note(l.size());
        unsafe { System.alloc_zeroed(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        note(new);
        unsafe { System.realloc(p, l, new) }
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

fn assert_alloc_bound() {
    let largest = LARGEST.with(Cell::get);
    assert!(
        largest <= MAX_ALLOC,
        "an allocation of {largest} bytes (the bound is {MAX_ALLOC})"
    );
}

fn asset() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/recordings/simple.mcap")
}

/// The first `n` messages of simple.mcap written as the recorder writes them
/// (its images cut to their top-left 32x24 pixels, to keep the tests fast).
fn recording(compression: Option<mcap::Compression>, n: usize) -> Vec<u8> {
    recording_in(compression, n, 25)
}

/// [`recording`] with a chunk closed every `per_chunk` messages.
fn recording_in(compression: Option<mcap::Compression>, n: usize, per_chunk: usize) -> Vec<u8> {
    let src = std::fs::read(asset()).unwrap();
    let profile = Profile::Foxglove { jpeg: None };
    let mut w = mcapfmt::write_options(compression, profile)
        .create(Cursor::new(Vec::new()))
        .unwrap();
    let mut ids = BTreeMap::new();
    let mut buf = Vec::new();
    for (i, m) in mcap::MessageStream::new(&src).unwrap().take(n).enumerate() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().map(|s| s.name.as_str());
        let kind = mcapfmt::channel_kind(&m.channel.metadata, schema).unwrap();
        let id = *ids.entry(m.channel.topic.clone()).or_insert_with(|| {
            mcapfmt::add_channel(&mut w, &m.channel.topic, kind, profile)
                .unwrap()
                .unwrap()
        });
        let mut data: &[u8] = &m.data;
        if kind == jderobot::interfaces::Kind::Image {
            let d = mcapfmt::decode_mcap(kind, &m).unwrap();
            let Recorded::Image(img) = d.value else {
                panic!("an image")
            };
            let (w, h) = (32, 24);
            let mut small = Vec::new();
            for y in 0..h {
                let row = y * img.width as usize * 3;
                small.extend_from_slice(&img.data[row..row + w * 3]);
            }
            let snap = Snapshot::Image(Arc::new(Sample {
                clock: d.clock,
                stamp: Instant::now(),
                time: mcapfmt::from_nanos(d.time_ns),
                value: Image {
                    width: w as u32,
                    height: h as u32,
                    data: small,
                },
            }));
            assert!(mcapfmt::encode(profile, &m.channel.topic, &snap, &mut buf));
            data = &buf;
        }
        let header = mcap::records::MessageHeader {
            channel_id: id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        w.write_to_known_channel(&header, data).unwrap();
        if i % per_chunk == per_chunk - 1 {
            w.flush().unwrap();
        }
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

/// The three forms of the first `n` messages.
fn forms(n: usize) -> Vec<(&'static str, Vec<u8>)> {
    vec![
        ("zstd", recording(Some(mcap::Compression::Zstd), n)),
        ("lz4", recording(Some(mcap::Compression::Lz4), n)),
        ("none", recording(None, n)),
    ]
}

/// A message as read: (topic, sequence, log time, data).
type Fingerprint = (String, u32, u64, Vec<u8>);

/// What the replay's loop does with a file: every readable message decoded (the
/// errors counted, never a panic); the messages read.
fn replay_pass(bytes: &[u8]) -> Result<(reader::Outcome, Vec<Fingerprint>), String> {
    let mut seen = Vec::new();
    let o = reader::read_messages(bytes, |m| {
        let schema = m.channel.schema.as_ref().map(|s| s.name.as_str());
        if let Some(kind) = mcapfmt::channel_kind(&m.channel.metadata, schema) {
            let _ = mcapfmt::decode_read(kind, m);
        }
        seen.push((
            m.channel.topic.clone(),
            m.sequence,
            m.log_time,
            m.data.to_vec(),
        ));
        ControlFlow::Continue(())
    })?;
    Ok((o, seen))
}

/// The top-level records of an intact file: (offset, opcode, end).
fn records(bytes: &[u8]) -> Vec<(usize, u8, usize)> {
    let mut v = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() - 8 {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        v.push((at, bytes[at], at + 9 + len));
        at += 9 + len;
    }
    v
}

fn chunks(bytes: &[u8]) -> Vec<(usize, usize)> {
    records(bytes)
        .into_iter()
        .filter(|r| r.1 == 0x06)
        .map(|r| (r.0, r.2))
        .collect()
}

fn panic_text(e: &Box<dyn std::any::Any + Send>) -> String {
    e.downcast_ref::<String>()
        .cloned()
        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_default()
}

/// Deterministic positions: every byte of the first 100 (magic, header, the
/// first chunk's header) and of the last 100 (summary, footer), and 100 spread
/// over the rest by an LCG.
fn positions(len: usize) -> Vec<usize> {
    let mut p: Vec<usize> = (0..100.min(len)).collect();
    p.extend(len.saturating_sub(100)..len);
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    for _ in 0..100 {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        p.push((x >> 33) as usize % len);
    }
    p.sort_unstable();
    p.dedup();
    p
}

/// R1, R2: one byte flipped at a time in each form; info's summary and the
/// replay's pass on every copy: no panic, no allocation over the bound, a clear
/// error or a partial result; an intact-looking copy gives exactly the
/// original's messages, a damaged one a subset of them.
#[test]
fn every_single_byte_flip_is_read_without_panic_or_huge_allocation() {
    measure_allocations();
    let quiet = common::quiet_panics();
    let mut failures = Vec::new();
    let mut copies = 0;
    for (form, file) in forms(100) {
        let (_, original) = replay_pass(&file).unwrap();
        assert_eq!(original.len(), 100, "{form}");
        let all: HashSet<&Fingerprint> = original.iter().collect();
        for (i, &p) in positions(file.len()).iter().enumerate() {
            // Each position flipped one way: all bits, the lowest, the highest.
            for mask in [[0xFFu8, 0x01, 0x80][i % 3]] {
                let mut copy = file.clone();
                copy[p] ^= mask;
                copies += 1;
                let r = std::panic::catch_unwind(|| {
                    let s = Summary::of(&copy);
                    (s, replay_pass(&copy))
                });
                let (s, pass) = match r {
                    Ok(x) => x,
                    Err(e) => {
                        failures.push(format!(
                            "{form} byte {p} ^{mask:#x}: panic: {}",
                            panic_text(&e)
                        ));
                        continue;
                    }
                };
                let (Ok(s), Ok((_, seen))) = (s, pass) else {
                    // Not MCAP at all: only the magic can say that.
                    assert!(p < 8, "{form} byte {p}: an error past the magic");
                    continue;
                };
                if s.intact() {
                    if seen != original {
                        failures.push(format!(
                            "{form} byte {p} ^{mask:#x}: reported intact, but the messages differ"
                        ));
                    }
                } else if let Some(m) = seen.iter().find(|m| !all.contains(m)) {
                    failures.push(format!(
                        "{form} byte {p} ^{mask:#x}: a damaged message was used: {} seq {}",
                        m.0, m.1
                    ));
                }
                assert_eq!(s.messages as usize, seen.len());
            }
        }
    }
    drop(quiet);
    assert!(
        failures.is_empty(),
        "{} of {copies} copies failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
    assert_alloc_bound();
}

/// R1, R2 through the binary: `jderobot info` and `check` of a replay conf on
/// damaged copies whose chunk lengths and sizes say gigabytes, under a 1 GiB
/// address space: no abort, the damage reported with its offset.
#[test]
fn info_on_damaged_sizes_neither_aborts_nor_panics() {
    let dir = tempfile::tempdir().unwrap();
    for (form, file) in forms(200) {
        let c = chunks(&file);
        let (at, _) = c[c.len() / 2];
        // The record length's top byte, and the chunk's uncompressed_size's.
        for (i, off) in [(0, at + 8), (1, at + 9 + 16 + 7), (2, at + 9 + 16 + 4)] {
            let mut copy = file.clone();
            copy[off] ^= 0x7F;
            let path = dir.path().join(format!("{form}{i}.mcap"));
            std::fs::write(&path, &copy).unwrap();
            let out = Command::new("sh")
                .arg("-c")
                .arg(format!(
                    "ulimit -v 1048576; exec {BIN} info {}",
                    path.display()
                ))
                .stdin(Stdio::null())
                .output()
                .unwrap();
            let text = String::from_utf8_lossy(&out.stdout);
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(
                out.status.success(),
                "{form} {i}: {:?}\n{text}\n{err}",
                out.status
            );
            assert!(
                text.contains(&format!("corrupt: at byte {at}")) && text.contains("complete: NO"),
                "{form} {i}: {text}"
            );
            assert!(!text.contains("cut short"), "{form} {i}: {text}");
            // `check` of a replay conf loads the file as a run would.
            let conf = dir.path().join(format!("{form}{i}.conf"));
            std::fs::write(
                &conf,
                format!("driver replay\nfile {form}{i}.mcap\nend_driver\nload_driver replay\n"),
            )
            .unwrap();
            let out = Command::new("sh")
                .arg("-c")
                .arg(format!(
                    "ulimit -v 1048576; exec {BIN} check {}",
                    conf.display()
                ))
                .stdin(Stdio::null())
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(out.status.success(), "{form} {i}: {:?}\n{err}", out.status);
            assert!(
                err.contains(&format!("is corrupt at byte {at}: ")),
                "{form} {i}: {err}"
            );
        }
    }
}

/// R3: one flipped pixel byte in an uncompressed recording: reported corrupt at
/// its chunk's offset (info and the replay's log), and the replay goes on with
/// the chunks after it.
#[test]
fn a_flipped_pixel_is_a_corrupt_chunk_and_the_replay_uses_the_rest() {
    measure_allocations();
    let file = recording(None, 200);
    let (_, original) = replay_pass(&file).unwrap();
    // The first image's pixels, found as they are in the (uncompressed) file.
    let img = original.iter().find(|m| m.0 == "colorA").unwrap();
    let pixels = &img.3[img.3.len() - 16..];
    let p = file.windows(16).position(|w| w == pixels).unwrap() + 8;
    let all = chunks(&file);
    let (chunk, chunk_end) = *all.iter().find(|(a, e)| (*a..*e).contains(&p)).unwrap();
    assert!(chunk_end < all[all.len() - 1].0, "chunks follow it");
    let mut copy = file.clone();
    copy[p] ^= 0x01;

    let s = Summary::of(&copy).unwrap();
    assert!(!s.intact(), "{s:?}");
    assert_eq!(s.corrupt.len(), 1, "{:?}", s.corrupt);
    assert!(
        s.corrupt[0].starts_with(&format!("at byte {chunk}: ")) && s.corrupt[0].contains("CRC"),
        "{:?}",
        s.corrupt
    );
    assert!(s.lost.is_none(), "{:?}", s.lost);
    let lost_msgs = original.len() as u64 - s.messages;
    assert!(
        lost_msgs > 0 && lost_msgs <= 25,
        "{} of 200 read",
        s.messages
    );

    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.mcap"), &copy).unwrap();
    let info = Command::new(BIN)
        .arg("info")
        .arg(dir.path().join("p.mcap"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(info.status.success());
    assert!(
        text.contains(&format!("corrupt: at byte {chunk}: ")) && text.contains("complete: NO"),
        "{text}"
    );
    assert!(!text.contains("complete: yes"), "{text}");

    // The replay: warns with the offset, and replays past the chunk (the last
    // laser message recorded back is the file's last).
    std::fs::write(
        dir.path().join("r.conf"),
        "driver replay\nfile p.mcap\nspeed max\nprovides laser\nend_driver\n\
         service recorder\nfile back.mcap\nrecords laser\nend_service\n\
         load_driver replay\nload_service recorder\n",
    )
    .unwrap();
    let out = Command::new(BIN)
        .args(["--headless", "--no-shell", "--for", "2"])
        .arg(dir.path().join("r.conf"))
        .current_dir(dir.path())
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains(&format!("is corrupt at byte {chunk}: ")),
        "the replay should warn: {err}"
    );
    let back = std::fs::read(dir.path().join("back.mcap")).unwrap();
    let (_, back) = replay_pass(&back).unwrap();
    let last = original.iter().rev().find(|m| m.0 == "laser").unwrap();
    let got = back.iter().rev().find(|m| m.0 == "laser").unwrap();
    let decode = |m: &Fingerprint| {
        mcapfmt::decode_message(
            &m.0,
            jderobot::interfaces::Kind::Laser,
            "foxglove.LaserScan",
            "protobuf",
            m.1,
            m.2,
            &m.3,
        )
        .unwrap()
        .value
    };
    assert_eq!(
        decode(got),
        decode(last),
        "the replay ends on the file's last laser"
    );
    assert_alloc_bound();
}

/// R4: a damaged record length in the middle is corruption at its offset, and
/// the chunks after it are read; a file cut short says so, and both together
/// say both.
#[test]
fn mid_file_corruption_is_not_cut_short_and_a_cut_file_is() {
    measure_allocations();
    for (form, file) in forms(200) {
        let c = chunks(&file);
        let (at, end) = c[2];
        let (_, original) = replay_pass(&file).unwrap();

        // The chunk record's length, its top byte damaged: past the end.
        let mut copy = file.clone();
        copy[at + 8] ^= 0x40;
        let s = Summary::of(&copy).unwrap();
        assert!(s.lost.is_none(), "{form}: {:?}", s.lost);
        assert!(
            s.corrupt.len() == 1 && s.corrupt[0].starts_with(&format!("at byte {at}: ")),
            "{form}: {:?}",
            s.corrupt
        );
        let report = s.report(Path::new("x.mcap"));
        assert!(
            report.contains("corrupt") && !report.contains("cut short"),
            "{form}: {report}"
        );
        assert_eq!(s.messages, 175, "{form}: the other chunks are read");

        // Its length off by a little (in the file): corrupt, the rest read.
        let mut copy = file.clone();
        copy[at + 1] ^= 0x03;
        let s = Summary::of(&copy).unwrap();
        assert!(s.lost.is_none() && !s.corrupt.is_empty(), "{form}: {s:?}");
        assert!(
            s.corrupt[0].starts_with(&format!("at byte {at}: ")),
            "{form}: {:?}",
            s.corrupt
        );
        assert!(s.messages >= 150, "{form}: {}", s.messages);

        // A file cut in its fifth chunk: cut short, nothing corrupt.
        let (at5, end5) = c[4];
        let cut = &file[..(at5 + end5) / 2];
        let s = Summary::of(cut).unwrap();
        assert!(s.corrupt.is_empty(), "{form}: {:?}", s.corrupt);
        let lost = s.lost.clone().expect("cut short");
        assert!(
            lost.starts_with(&format!("at byte {at5}: ")),
            "{form}: {lost}"
        );
        assert!(s.report(Path::new("x")).contains("cut short"));
        assert_eq!(s.messages, 100, "{form}: the four whole chunks");
        let (_, seen) = replay_pass(cut).unwrap();
        assert_eq!(&seen[..], &original[..100]);

        // A file cut at a record boundary (after the fifth chunk): cut short.
        let s = Summary::of(&file[..end5]).unwrap();
        assert!(s.corrupt.is_empty() && s.lost.is_some(), "{form}: {s:?}");

        // Both: a damaged length in chunk 3 of a file cut in chunk 5.
        let mut both = cut.to_vec();
        both[at + 8] ^= 0x40;
        let s = Summary::of(&both).unwrap();
        assert!(
            s.corrupt.len() == 1 && s.corrupt[0].starts_with(&format!("at byte {at}: ")),
            "{form}: {:?}",
            s.corrupt
        );
        assert!(
            s.lost
                .as_deref()
                .is_some_and(|l| l.starts_with(&format!("at byte {at5}: "))),
            "{form}: {s:?}"
        );
        assert_eq!(s.messages, 75, "{form}");
        let _ = end;
    }
    assert_alloc_bound();
}

/// The other CRCs MCAP has: the data section's and an attachment's (0: not set).
#[test]
fn data_section_and_attachment_crcs_are_checked() {
    let mut w = mcap::WriteOptions::new()
        .compression(None)
        .calculate_data_section_crc(true)
        .create(Cursor::new(Vec::new()))
        .unwrap();
    let ch = w.add_channel(0, "t", "json", &BTreeMap::new()).unwrap();
    let header = mcap::records::MessageHeader {
        channel_id: ch,
        sequence: 1,
        log_time: 5,
        publish_time: 5,
    };
    w.write_to_known_channel(&header, b"{}").unwrap();
    w.attach(&mcap::Attachment {
        log_time: 1,
        create_time: 1,
        name: "a".into(),
        media_type: "text/plain".into(),
        data: std::borrow::Cow::Borrowed(b"attachment bytes"),
    })
    .unwrap();
    w.finish().unwrap();
    let file = w.into_inner().into_inner();
    let s = Summary::of(&file).unwrap();
    assert!(s.intact() && s.messages == 1, "{s:?}");

    // A byte of the attachment's data: its CRC (and the data section's) say so.
    let p = file.windows(10).position(|w| w == b"attachment").unwrap();
    let mut copy = file.clone();
    copy[p] ^= 0x20;
    let s = Summary::of(&copy).unwrap();
    assert!(
        s.corrupt.iter().any(|c| c.contains("attachment's CRC")),
        "{:?}",
        s.corrupt
    );
    assert_eq!(s.messages, 1);

    // The header's library string is covered only by the data section's CRC.
    let p = file.windows(4).position(|w| w == b"mcap").unwrap();
    let mut copy = file.clone();
    copy[p] ^= 0x20;
    let s = Summary::of(&copy).unwrap();
    assert!(
        s.corrupt.iter().any(|c| c.contains("data section's CRC")),
        "{:?}",
        s.corrupt
    );
}

/// Not a regular file: refused at once (a device would never end).
#[test]
fn a_device_or_a_directory_is_not_read() {
    let e = Summary::read(Path::new("/dev/zero"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a regular file"), "{e}");
    let e = Summary::read(Path::new("/")).unwrap_err().to_string();
    assert!(e.contains("a directory"), "{e}");
}

/// A fuzz smoke: 10,000 structure-aware mutations (record lengths, chunk sizes
/// and CRCs set to extremes, bytes flipped, ranges cut, doubled or zeroed,
/// truncation; 1 to 3 each) of small recordings in the three forms, each read
/// as `info` reads it (and every fourth as the replay does, decoding each
/// message): no panic, the allocation bound held.
#[test]
fn fuzz_smoke_ten_thousand_structured_mutations() {
    measure_allocations();
    let quiet = common::quiet_panics();
    let bases: Vec<Vec<u8>> = vec![
        recording_in(Some(mcap::Compression::Zstd), 24, 8),
        recording_in(Some(mcap::Compression::Lz4), 24, 8),
        recording_in(None, 24, 8),
    ];
    let fields: Vec<Vec<usize>> = bases
        .iter()
        .map(|b| {
            // Record lengths, and a chunk's uncompressed_size, crc and records length.
            let mut f = Vec::new();
            for (at, op, _) in records(b) {
                f.push(at + 1);
                if op == 0x06 {
                    f.extend([at + 9 + 16, at + 9 + 24]);
                    let n = u32::from_le_bytes(b[at + 37..at + 41].try_into().unwrap()) as usize;
                    f.push(at + 41 + n);
                }
            }
            f
        })
        .collect();
    let mut x: u64 = 42;
    let mut rnd = |n: usize| {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x % n.max(1) as u64) as usize
    };
    let extremes = [
        0u64,
        1,
        u64::MAX,
        u64::MAX / 2,
        1 << 32,
        1 << 40,
        0x7F7F_7F7F_7F7F_7F7F,
    ];
    let mut failures = Vec::new();
    for i in 0..10_000 {
        let k = rnd(bases.len());
        let mut b = bases[k].clone();
        for _ in 0..1 + rnd(3) {
            let len = b.len();
            match rnd(8) {
                0 | 1 => {
                    let p = rnd(len);
                    b[p] ^= 1 << rnd(8);
                }
                2 => {
                    let f = fields[k][rnd(fields[k].len())];
                    let v = if rnd(2) == 0 {
                        extremes[rnd(extremes.len())]
                    } else {
                        rnd(2 * len) as u64
                    };
                    if f + 8 <= len {
                        b[f..f + 8].copy_from_slice(&v.to_le_bytes());
                    }
                }
                3 => {
                    let f = fields[k][rnd(fields[k].len())];
                    if f + 4 <= len {
                        b[f..f + 4].copy_from_slice(&(rnd(usize::MAX) as u32).to_le_bytes());
                    }
                }
                4 => b.truncate(rnd(len)),
                5 => {
                    let (a, n) = (rnd(len), rnd(256));
                    let end = (a + n).min(len);
                    let dup = b[a..end].to_vec();
                    b.splice(a..a, dup);
                }
                6 => {
                    let (a, n) = (rnd(len), rnd(256));
                    let end = (a + n).min(len);
                    b.drain(a..end);
                }
                _ => {
                    let (a, n) = (rnd(len), rnd(64));
                    let end = (a + n).min(len);
                    b[a..end].fill(if rnd(2) == 0 { 0 } else { 0xFF });
                }
            }
        }
        if let Err(e) = std::panic::catch_unwind(|| {
            let _ = Summary::of(&b);
            // The replay's pass also decodes every message (slow in a debug
            // build): every fourth input.
            if i % 4 == 0 {
                let _ = replay_pass(&b);
            }
        }) {
            failures.push(format!("input {i}: {}", panic_text(&e)));
        }
    }
    drop(quiet);
    assert!(
        failures.is_empty(),
        "{} panics:\n{}",
        failures.len(),
        failures.join("\n")
    );
    assert_alloc_bound();
}

/// An unchunked file (messages at the top level, as some writers make them) is
/// read; a damaged message length there is corruption at its offset (the
/// messages after it are not recovered: resync looks for chunks).
#[test]
fn unchunked_files_are_read() {
    let mut w = mcap::WriteOptions::new()
        .use_chunks(false)
        .create(Cursor::new(Vec::new()))
        .unwrap();
    let ch = w.add_channel(0, "t", "json", &BTreeMap::new()).unwrap();
    for i in 0..3 {
        let header = mcap::records::MessageHeader {
            channel_id: ch,
            sequence: i,
            log_time: i as u64,
            publish_time: i as u64,
        };
        w.write_to_known_channel(&header, b"{}").unwrap();
    }
    w.finish().unwrap();
    let file = w.into_inner().into_inner();
    let s = Summary::of(&file).unwrap();
    assert!(s.intact() && s.messages == 3, "{s:?}");
    let at = records(&file).iter().find(|r| r.1 == 0x05).unwrap().0;
    let mut copy = file.clone();
    copy[at + 8] ^= 0x10;
    let s = Summary::of(&copy).unwrap();
    assert!(
        s.corrupt
            .first()
            .is_some_and(|c| c.starts_with(&format!("at byte {at}: "))),
        "{s:?}"
    );
    assert!(s.lost.is_none() && s.messages < 3, "{s:?}");
}
