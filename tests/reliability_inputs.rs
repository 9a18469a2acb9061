//! Probe suite of issue 29's input items: hostile NumPy files (header fuzz, shape products that
//! wrap modulo 2^64, huge header lengths, an `.npz` inflate bomb, FIFOs and devices), an unknown
//! key inside a nested `[method]` table, a closed standard output, out-of-range `export --fps`,
//! and the viewer's HTTP server (slow clients, many connections, unfinished bodies, duplicate
//! `Content-Length`, `--host ::` and `--host localhost`).
//!
//! Every probe asserts something that could fail: the exit status, no "panicked" on stderr, the
//! message naming the file / key / flag, a bounded time or memory. Each test prints how many
//! cases it ran (`cargo test -- --nocapture` shows them). Bounded to well under a minute.

mod common;
mod view_support;

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use common::{fresh_dir, meshdeco, output_text};
use meshdeco::mesh::npy::load_npy_with_faces;
use meshdeco::view::http::{self, Limits, Request, Response};

/// The binary.
const BIN: &str = env!("CARGO_BIN_EXE_meshdeco");

/// A small deterministic generator (xorshift64*), so that a failing case can be replayed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// Runs the binary with `args` in `cwd`, stdout and stderr to files, killed after `limit`:
/// (exit status, `None` when it had to be killed; stdout; stderr).
fn run_bounded(args: &[&str], cwd: &Path, limit: Duration) -> (Option<ExitStatus>, String, String) {
    let tag = format!("{}-{:?}", std::process::id(), std::thread::current().id());
    let out_path = cwd.join(format!(".stdout-{tag}"));
    let err_path = cwd.join(format!(".stderr-{tag}"));
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out_path).unwrap())
        .stderr(std::fs::File::create(&err_path).unwrap())
        .spawn()
        .expect("start meshdeco");
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break Some(s);
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();
    let (o, e) = (read(&out_path), read(&err_path));
    let _ = std::fs::remove_file(out_path);
    let _ = std::fs::remove_file(err_path);
    (status, o, e)
}

/// Asserts a refused run: it ended in time with status 1, did not panic, and its stderr
/// contains every one of `needles`.
fn assert_refused(what: &str, run: &(Option<ExitStatus>, String, String), needles: &[&str]) {
    let (status, out, err) = run;
    let status = status.unwrap_or_else(|| panic!("{what}: still running at the time limit (a hang)\n{out}{err}"));
    assert_eq!(status.code(), Some(1), "{what}: exit status {status}\n{out}{err}");
    assert!(!err.contains("panicked"), "{what}: panicked\n{err}");
    for n in needles {
        assert!(err.contains(n), "{what}: stderr lacks `{n}`:\n{err}");
    }
}

// ---------------------------------------------------------------------------------------------
// NumPy inputs (items 3, 4, 5, 6)
// ---------------------------------------------------------------------------------------------

/// A `.npy` image: magic, version `major`.0, the header text padded as NumPy pads it, `data`.
fn npy(major: u8, text: &str, data: &[u8]) -> Vec<u8> {
    let pre = if major == 1 { 10 } else { 12 };
    let mut header = text.to_string();
    while !(pre + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY".to_vec();
    out.extend([major, 0]);
    if major == 1 {
        out.extend((header.len() as u16).to_le_bytes());
    } else {
        out.extend((header.len() as u32).to_le_bytes());
    }
    out.extend(header.as_bytes());
    out.extend(data);
    out
}

fn header_text(descr: &str, fortran: bool, shape: &str) -> String {
    format!("{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}", if fortran { "True" } else { "False" })
}

/// `frames` frames of the 4-vertex template, float64, C order: value = 100 f + 10 v + c.
fn good_npy(frames: usize) -> Vec<u8> {
    let mut data = Vec::new();
    for f in 0..frames {
        for v in 0..4 {
            for c in 0..3 {
                data.extend(((100 * f + 10 * v + c) as f64).to_le_bytes());
            }
        }
    }
    npy(1, &header_text("<f8", false, &format!("({frames}, 4, 3)")), &data)
}

/// The template's faces (4 vertices, 2 triangles) and an OBJ of it.
const TEMPLATE_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n";
const FACES: [[usize; 3]; 2] = [[0, 1, 2], [0, 2, 3]];

/// Loads `bytes` written to `path` through the library's NumPy reader, catching a panic:
/// Ok(result) or Err(panic message).
fn load_bytes(path: &Path, bytes: &[u8]) -> Result<meshdeco::Result<meshdeco::mesh::MeshSequence>, String> {
    std::fs::write(path, bytes).unwrap();
    std::panic::catch_unwind(|| load_npy_with_faces(path, None, 4, FACES.to_vec())).map_err(|p| {
        p.downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_default()
    })
}

/// Checks one outcome: no panic; a sequence is finite and of 4 vertices; an error names the file.
fn check_outcome(case: &str, path: &Path, r: Result<meshdeco::Result<meshdeco::mesh::MeshSequence>, String>) -> bool {
    match r {
        Err(panic) => panic!("{case}: panicked: {panic}"),
        Ok(Ok(seq)) => {
            assert!(!seq.frames.is_empty(), "{case}: no frame");
            for f in &seq.frames {
                assert_eq!(f.len(), 4, "{case}");
                assert!(f.iter().flatten().all(|x| x.is_finite()), "{case}: non-finite value accepted");
            }
            true
        }
        Ok(Err(e)) => {
            let m = e.to_string();
            assert!(m.contains(&path.display().to_string()), "{case}: the error does not name the file: {m}");
            false
        }
    }
}

#[test]
fn npy_header_cases_are_clear_errors() {
    let d = fresh_dir("rel-inputs", "npy-cases");
    let p = d.join("x.npy");
    let data96 = vec![0u8; 96];
    // (case, bytes, needle of the error; "" = must load)
    let wrap = 1u64 << 61; // 2^61 × 4 × 3 × 8 ≡ 0 (mod 2^64)
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("valid", good_npy(2), ""),
        ("valid v2", npy(2, &header_text("<f8", false, "(1, 4, 3)"), &[0u8; 96]), ""),
        ("valid f4 big-endian fortran", npy(1, &header_text(">f4", true, "(2, 4, 3)"), &[0u8; 96]), ""),
        ("product wraps to 0", npy(1, &header_text("<f8", false, &format!("({wrap}, 4, 3)")), &[]), "2^64"),
        (
            "product wraps to 96 bytes, 96 present",
            npy(1, &header_text("<f8", false, &format!("({}, 4, 3)", wrap + 1)), &data96),
            "2^64",
        ),
        (
            "frames × vertices wraps",
            npy(1, &header_text("<f8", false, &format!("({}, 4, 3)", u64::MAX / 2)), &data96),
            "2^64",
        ),
        ("dimension past u64", npy(1, &header_text("<f8", false, "(18446744073709551616, 4, 3)"), &data96), "2^64"),
        ("negative dimension", npy(1, &header_text("<f8", false, "(-1, 4, 3)"), &data96), "non-negative integer"),
        ("10^12 frames", npy(1, &header_text("<f8", false, "(1000000000000, 4, 3)"), &data96), "bytes of data"),
        ("zero frames", npy(1, &header_text("<f8", false, "(0, 4, 3)"), &[]), "no frame"),
        ("wrong vertex count", npy(1, &header_text("<f8", false, "(1, 5, 3)"), &[0u8; 120]), "template mesh has 4"),
        ("2-d", npy(1, &header_text("<f8", false, "(4, 3)"), &data96), "expected (frames, 4, 3)"),
        ("int dtype", npy(1, &header_text("<i4", false, "(1, 4, 3)"), &data96), "not float32 or float64"),
        (
            "structured dtype",
            npy(1, "{'descr': [('x', '<f8')], 'fortran_order': False, 'shape': (1, 4, 3), }", &data96),
            "not float32 or float64",
        ),
        ("truncated data", npy(1, &header_text("<f8", false, "(2, 4, 3)"), &data96), "bytes of data"),
        ("extra key", npy(1, "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 4, 3), 'x': 1}", &data96), "`x`"),
        ("missing key", npy(1, "{'descr': '<f8', 'shape': (1, 4, 3)}", &data96), "required"),
        ("not a dict", npy(1, "[1, 2, 3]", &data96), "expected `{`"),
        ("deep nesting", npy(1, &format!("{{'descr': '<f8', 'shape': {}", "(".repeat(9000)), &[]), "header"),
        ("version 9", [&b"\x93NUMPY\x09\x00\x10\x00"[..], &[b' '; 16]].concat(), "version 9.0"),
        ("no magic", b"PK\x03\x04 not numpy at all".to_vec(), "magic"),
        ("empty file", Vec::new(), "too short"),
        ("magic only", b"\x93NUMPY\x01".to_vec(), "too short"),
    ];
    // Header lengths: 4 GiB and NumPy's limit + 1 (v2), and one past the end (v1).
    let mut huge = b"\x93NUMPY\x02\x00".to_vec();
    huge.extend(u32::MAX.to_le_bytes());
    huge.extend(b"{'descr': '<f8'");
    let mut over = b"\x93NUMPY\x02\x00".to_vec();
    over.extend(10_001u32.to_le_bytes());
    over.extend(vec![b' '; 10_001]);
    let mut past = b"\x93NUMPY\x01\x00".to_vec();
    past.extend(5000u16.to_le_bytes());
    past.extend(b"{'descr': '<f8'}");
    let more: Vec<(&str, Vec<u8>, &str)> = vec![
        ("4 GiB header", huge, "longer than NumPy's limit of 10000"),
        ("header of 10001 bytes", over, "longer than NumPy's limit of 10000"),
        ("header past the end", past, "runs past the end"),
    ];
    let mut n = 0;
    for (case, bytes, needle) in cases.into_iter().chain(more) {
        let t0 = Instant::now();
        let r = load_bytes(&p, &bytes);
        assert!(t0.elapsed() < Duration::from_secs(2), "{case}: took {:?}", t0.elapsed());
        match &r {
            Ok(Ok(_)) => assert!(needle.is_empty(), "{case}: accepted, expected an error with `{needle}`"),
            Ok(Err(e)) => {
                assert!(!needle.is_empty(), "{case}: refused: {e}");
                assert!(e.to_string().contains(needle), "{case}: `{e}` lacks `{needle}`");
            }
            Err(_) => {}
        }
        check_outcome(case, &p, r);
        n += 1;
    }
    // The values of the valid files are the ones written.
    std::fs::write(&p, good_npy(2)).unwrap();
    let seq = load_npy_with_faces(&p, None, 4, FACES.to_vec()).unwrap();
    assert_eq!(seq.frames[1][3], [130.0, 131.0, 132.0]);
    eprintln!("npy header cases: {n}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn npy_header_fuzz_never_panics() {
    let d = fresh_dir("rel-inputs", "npy-fuzz");
    let p = d.join("f.npy");
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let dims: [u64; 16] = [
        0,
        1,
        2,
        3,
        4,
        5,
        1 << 32,
        1 << 60,
        1 << 61,
        (1 << 61) + 1,
        1 << 62,
        1 << 63,
        u64::MAX,
        u64::MAX / 12 + 1,
        u64::MAX / 24 + 1,
        768_614_336_404_564_651,
    ];
    let descrs = ["<f8", ">f8", "<f4", ">f4", "=f8", "|f8", "f8", "<i4", "<f2", "<c16", "O", "", "<f8<f8", "<F8"];
    let base = good_npy(3);
    let (mut loaded, mut refused) = (0usize, 0usize);
    let cases = 3000;
    for i in 0..cases {
        let bytes = match i % 7 {
            // A header from the grammar with random dtype, order and shape.
            0 | 1 => {
                let rank = rng.below(5);
                let shape: Vec<String> = (0..rank)
                    .map(|k| match rng.below(3) {
                        0 => rng.pick(&dims).to_string(),
                        1 if k == 1 => "4".into(),
                        _ => rng.below(6).to_string(),
                    })
                    .collect();
                let shape = match (rank, rng.below(3)) {
                    (1, _) => format!("({},)", shape[0]),
                    (_, 0) => format!("[{}]", shape.join(",")),
                    _ => format!("({})", shape.join(", ")),
                };
                let data = vec![0x3Fu8; rng.below(400)];
                npy(
                    1 + rng.below(3) as u8,
                    &header_text(descrs[rng.below(descrs.len())], rng.below(2) == 0, &shape),
                    &data,
                )
            }
            // Bytes of the header flipped.
            2 => {
                let mut b = base.clone();
                for _ in 0..1 + rng.below(4) {
                    let at = rng.below(80);
                    b[at] = rng.next() as u8;
                }
                b
            }
            // Truncated anywhere.
            3 => base[..rng.below(base.len())].to_vec(),
            // The header length field (and version) replaced.
            4 => {
                let mut b = base.clone();
                if rng.below(2) == 0 {
                    b[8..10].copy_from_slice(&(rng.next() as u16).to_le_bytes());
                } else {
                    b[6] = 2;
                    let r = rng.next() as u32;
                    let len = *rng.pick(&[u32::MAX, 1 << 31, 10_000, 10_001, 1 << 20, r]);
                    b.splice(8..10, len.to_le_bytes());
                }
                b
            }
            // Random printable header text.
            5 => {
                let alphabet = b"{}()[]',: 0123456789TrueFalsdcrpothsfL<>=|\"\\";
                let text: Vec<u8> = (0..rng.below(200)).map(|_| *rng.pick(alphabet)).collect();
                npy(1, &String::from_utf8(text).unwrap(), &vec![0u8; rng.below(200)])
            }
            // Random bytes inserted into the header.
            _ => {
                let mut b = base.clone();
                let at = 10 + rng.below(60);
                let junk: Vec<u8> = (0..1 + rng.below(8)).map(|_| rng.next() as u8).collect();
                b.splice(at..at, junk);
                b
            }
        };
        let t0 = Instant::now();
        let ok = check_outcome(&format!("fuzz case {i}"), &p, load_bytes(&p, &bytes));
        assert!(t0.elapsed() < Duration::from_secs(2), "fuzz case {i}: took {:?}", t0.elapsed());
        if ok { loaded += 1 } else { refused += 1 }
    }
    assert!(refused > cases / 2 && loaded > 0, "loaded {loaded}, refused {refused}: the fuzz did not reach both ends");
    eprintln!("npy header fuzz: {cases} cases, {loaded} loaded, {refused} refused, 0 panics");
    std::fs::remove_dir_all(&d).unwrap();
}

/// Peak resident memory of this process (VmHWM, kB).
fn peak_rss_kb() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    s.lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// An `.npz` whose member `a.npy` has a header of `frames` frames (4 vertices) and then
/// `inflated` bytes of zeros (deflated: a small archive).
fn npz_bomb(path: &Path, frames: usize, inflated: usize) {
    let f = std::fs::File::create(path).unwrap();
    let mut zip = zip::ZipWriter::new(f);
    let opts = zip::write::FileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated)
        .compression_level(Some(1))
        .large_file(true);
    zip.start_file("a.npy", opts).unwrap();
    zip.write_all(&npy(1, &header_text("<f8", false, &format!("({frames}, 4, 3)")), &[])).unwrap();
    let chunk = vec![0u8; 1 << 20];
    let mut left = inflated;
    while left > 0 {
        let n = left.min(chunk.len());
        zip.write_all(&chunk[..n]).unwrap();
        left -= n;
    }
    zip.finish().unwrap();
}

/// Rewrites the uncompressed size of every entry of the zip at `path` (local and central
/// headers) to `size`: a member that claims less than it inflates to.
fn claim_size(path: &Path, size: u32) {
    let mut b = std::fs::read(path).unwrap();
    let mut i = 0;
    while i + 4 <= b.len() {
        match &b[i..i + 4] {
            b"PK\x03\x04" => b[i + 22..i + 26].copy_from_slice(&size.to_le_bytes()),
            b"PK\x01\x02" => b[i + 24..i + 28].copy_from_slice(&size.to_le_bytes()),
            _ => {}
        }
        i += 1;
    }
    std::fs::write(path, b).unwrap();
}

#[test]
fn npz_inflate_bomb_stops_at_the_implied_size() {
    let d = fresh_dir("rel-inputs", "npz-bomb");
    let p = d.join("bomb.npz");
    // 1 GiB of zeros behind a header of 10 000 frames (960 000 bytes of data); the archive says
    // the member is 1 MiB. Read to its end, it would take a gigabyte.
    npz_bomb(&p, 10_000, 1 << 30);
    claim_size(&p, 1 << 20);
    let archive = std::fs::metadata(&p).unwrap().len();
    assert!(archive < 8 << 20, "the bomb is small: {archive} bytes");
    let before = peak_rss_kb();
    let t0 = Instant::now();
    let r = load_npy_with_faces(&p, Some("a"), 4, FACES.to_vec());
    let elapsed = t0.elapsed();
    let grown_mb = (peak_rss_kb().saturating_sub(before)) / 1024;
    // The header implies 960 000 bytes: that is what is read (10 000 frames of zeros).
    let seq = r.unwrap();
    assert_eq!(seq.frames.len(), 10_000);
    assert!(elapsed < Duration::from_secs(3), "reading the bomb took {elapsed:?}: inflated past the header's size");
    assert!(grown_mb < 200, "peak memory grew by {grown_mb} MB reading a bomb of {archive} bytes");
    // A header implying more than the member declares: refused before inflating.
    let p2 = d.join("bomb2.npz");
    npz_bomb(&p2, 100_000, 64 << 20);
    claim_size(&p2, 1 << 20);
    let e = load_npy_with_faces(&p2, Some("a"), 4, FACES.to_vec()).unwrap_err().to_string();
    assert!(e.contains("bomb2.npz") && e.contains("array `a`") && e.contains("bytes of data"), "{e}");
    // A member declaring more than an archive of its size can hold: refused.
    let p3 = d.join("bomb3.npz");
    npz_bomb(&p3, 10, 1 << 20);
    claim_size(&p3, u32::MAX);
    let e = load_npy_with_faces(&p3, Some("a"), 4, FACES.to_vec()).unwrap_err().to_string();
    assert!(e.contains("bomb3.npz") && e.contains("implausible"), "{e}");
    // The binary on the bomb as `data.path`: no panic, no abort, within a memory limit.
    std::fs::write(d.join("t.obj"), TEMPLATE_OBJ).unwrap();
    std::fs::write(
        d.join("c.toml"),
        "name = \"b\"\n[data]\npath = \"bomb2.npz\"\narray = \"a\"\ntemplate = \"t.obj\"\n[method]\nkind = \"pca\"\ncomponents = 1\n",
    )
    .unwrap();
    let r = run_bounded(&["train", "--config", "c.toml", "--out", "out"], &d, Duration::from_secs(20));
    assert_refused("train on an npz bomb", &r, &["bomb2.npz", "bytes of data"]);
    assert!(!d.join("out").exists(), "no artefact from refused data");
    eprintln!("npz bomb cases: 4");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn numpy_fifos_devices_and_directories_are_refused() {
    let d = fresh_dir("rel-inputs", "npy-fifo");
    std::fs::write(d.join("t.obj"), TEMPLATE_OBJ).unwrap();
    let fifo = d.join("fifo.npy");
    let made = Command::new("mkfifo").arg(&fifo).status().map(|s| s.success()).unwrap_or(false);
    assert!(made, "mkfifo");
    std::os::unix::fs::symlink("/dev/zero", d.join("zero.npy")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", d.join("zero.npz")).unwrap();
    std::fs::create_dir(d.join("dir.npy")).unwrap();
    let fifo_npz = d.join("fifo.npz");
    assert!(Command::new("mkfifo").arg(&fifo_npz).status().unwrap().success());
    let cases: [(&str, Option<&str>, &str); 5] = [
        ("fifo.npy", None, "not a regular file (a FIFO)"),
        ("fifo.npz", Some("a"), "not a regular file (a FIFO)"),
        ("zero.npy", None, "not a regular file (a character device)"),
        ("zero.npz", Some("a"), "not a regular file (a character device)"),
        ("dir.npy", None, "not a regular file (a directory)"),
    ];
    let mut n = 0;
    for (file, array, needle) in cases {
        // In the library, on a thread, so that a hang fails the test instead of stalling it.
        let path = d.join(file);
        let (tx, rx) = std::sync::mpsc::channel();
        let p = path.clone();
        std::thread::spawn(move || {
            let _ = tx.send(load_npy_with_faces(&p, array, 4, FACES.to_vec()).map(|_| ()).map_err(|e| e.to_string()));
        });
        let r = rx.recv_timeout(Duration::from_secs(5)).unwrap_or_else(|_| panic!("{file}: hangs"));
        let e = r.expect_err(file);
        assert!(e.contains(needle) && e.contains(file), "{file}: {e}");
        // And as `data.path` of `meshdeco train`.
        let array_line = array.map(|a| format!("array = \"{a}\"\n")).unwrap_or_default();
        std::fs::write(
            d.join("c.toml"),
            format!("name = \"f\"\n[data]\npath = \"{file}\"\n{array_line}template = \"t.obj\"\n[method]\nkind = \"pca\"\ncomponents = 1\n"),
        )
        .unwrap();
        let r = run_bounded(&["train", "--config", "c.toml", "--out", "out"], &d, Duration::from_secs(20));
        assert_refused(&format!("train on {file}"), &r, &[file, needle]);
        n += 2;
    }
    // `encode` of a model with frames given as a FIFO (the model's connectivity).
    let model = common::train_cli(&d, "m", "path = \"synthetic:bumps\"", "kind = \"pca\"\ncomponents = 2");
    let r = run_bounded(&["encode", model.to_str().unwrap(), "fifo.npy", "--out", "enc"], &d, Duration::from_secs(20));
    assert_refused("encode fifo.npy", &r, &["fifo.npy", "(a FIFO)"]);
    n += 1;
    eprintln!("numpy non-regular file cases: {n}");
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn numpy_wrapping_shape_through_the_binary() {
    // The issue's panic: the sequence loader of `train` on a shape whose product wraps.
    let d = fresh_dir("rel-inputs", "npy-bin");
    std::fs::write(d.join("t.obj"), TEMPLATE_OBJ).unwrap();
    let wrap = (1u64 << 61) + 1;
    let files: [(&str, Vec<u8>, &str); 3] = [
        ("wrap.npy", npy(1, &header_text("<f8", false, &format!("({wrap}, 4, 3)")), &[0u8; 96]), "2^64"),
        (
            "huge.npy",
            {
                let mut b = b"\x93NUMPY\x02\x00".to_vec();
                b.extend(u32::MAX.to_le_bytes());
                b
            },
            "longer than NumPy's limit",
        ),
        ("nan.npy", npy(1, &header_text("<f8", false, "(1, 4, 3)"), &[0xFFu8; 96]), "not finite"),
    ];
    for (file, bytes, needle) in &files {
        std::fs::write(d.join(file), bytes).unwrap();
        std::fs::write(
            d.join("c.toml"),
            format!("name = \"w\"\n[data]\npath = \"{file}\"\ntemplate = \"t.obj\"\n[method]\nkind = \"pca\"\ncomponents = 1\n"),
        )
        .unwrap();
        let r = run_bounded(&["train", "--config", "c.toml", "--out", "out"], &d, Duration::from_secs(20));
        assert_refused(&format!("train on {file}"), &r, &[file, needle]);
    }
    eprintln!("numpy binary cases: {}", files.len());
    std::fs::remove_dir_all(&d).unwrap();
}

// ---------------------------------------------------------------------------------------------
// Config (item 1)
// ---------------------------------------------------------------------------------------------

#[test]
fn unknown_keys_inside_nested_method_tables_are_named() {
    let cfg = |method: &str| format!("name = \"c\"\n[data]\npath = \"synthetic:tube\"\n[method]\n{method}\n");
    let cases: [(&str, &[&str]); 7] = [
        (
            "kind = \"splocs\"\nadmm = { rho = 10, iters = 10 }",
            &["method.admm.iters", "is not a key of method.admm", "iterations"],
        ),
        ("kind = \"splocs\"\n[method.admm]\nrho = 10.0\nsteps = 3", &["method.admm.steps", "rho"]),
        ("kind = \"splocs\"\nadmm = { rho = \"ten\" }", &["method.admm", "ten"]),
        ("kind = \"splocs\"\nadmm = 3", &["method.admm"]),
        ("kind = \"splocs\"\niters = 10", &["method.iters", "is not a key of kind = \"splocs\""]),
        ("kind = \"pca\"\nadmm = { rho = 10, iters = 10 }", &["method.admm", "does not apply to kind = \"pca\""]),
        ("kind = \"pca\"\nbogus = { a = 1 }", &["method.bogus", "is not a key of kind = \"pca\""]),
    ];
    for (method, needles) in cases {
        let e = meshdeco::config::Config::from_toml(&cfg(method)).expect_err(method).to_string();
        for n in needles {
            assert!(e.contains(n), "`{method}`: `{e}` lacks `{n}`");
        }
    }
    // Through the binary: exit 1 naming the key and the file, no panic.
    let d = fresh_dir("rel-inputs", "config");
    std::fs::write(d.join("c.toml"), cfg(cases[0].0)).unwrap();
    let r = run_bounded(&["train", "--config", "c.toml", "--out", "o"], &d, Duration::from_secs(20));
    assert_refused("nested unknown key", &r, &["method.admm.iters", "c.toml"]);
    assert!(!d.join("o").exists());
    eprintln!("nested config key cases: {}", cases.len() + 1);
    std::fs::remove_dir_all(&d).unwrap();
}

// ---------------------------------------------------------------------------------------------
// Closed standard output (item 2)
// ---------------------------------------------------------------------------------------------

/// Runs the binary with stdout a pipe whose reading end is closed before it writes:
/// (status, stderr).
fn run_with_closed_stdout(args: &[&str], cwd: &Path) -> (ExitStatus, String) {
    let mut child = Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let mut err = String::new();
    child.stderr.take().unwrap().read_to_string(&mut err).unwrap();
    (child.wait().unwrap(), err)
}

#[test]
fn a_closed_stdout_ends_quietly_with_status_141_after_the_work() {
    let d = fresh_dir("rel-inputs", "stdout");
    let model = common::train_cli(&d, "m", "path = \"synthetic:tube\"", "kind = \"pca\"\ncomponents = 3");
    let m = model.to_str().unwrap();
    std::fs::write(
        d.join("t.toml"),
        "name = \"t\"\n[data]\npath = \"synthetic:tube\"\n[method]\nkind = \"pca\"\ncomponents = 2\n",
    )
    .unwrap();
    std::fs::write(d.join("c.json"), r#"{"0": [0.01, 0.02, 0.03]}"#).unwrap();
    let cases: [(&[&str], Option<&str>); 8] = [
        (&["inspect", "--json", "synthetic:tube"], None),
        (&["inspect", "synthetic:tube"], None),
        (&["synthesize", m, "--weights", "0:0.5", "--out", "s.obj"], Some("s.obj")),
        (&["export", m, "--out", "e.glb", "--animation"], Some("e.glb")),
        (&["train", "--config", "t.toml", "--out", "trained"], Some("trained/manifest.json")),
        (&["components", m, "--out", "comps"], Some("comps/components.csv")),
        (&["pose", m, "--constraints", "c.json", "--out", "p.obj"], Some("p.obj")),
        (&["drag-bench", m, "synthetic:tube", "--drags", "3", "--pins", "1"], None),
    ];
    for (args, artefact) in cases {
        let (status, err) = run_with_closed_stdout(args, &d);
        assert_eq!(status.code(), Some(141), "{args:?}: status {status}, stderr:\n{err}");
        assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{args:?}: {err}");
        if let Some(a) = artefact {
            assert!(d.join(a).exists(), "{args:?}: {a} was not written");
        }
    }
    // The retrained artefact is complete: it loads (the manifest verifies every file).
    meshdeco::pipeline::load_model(&d.join("trained")).unwrap();
    meshdeco::export::read_glb(&d.join("e.glb")).unwrap();
    // Another write error (a full device) is an error with status 1, after the work too.
    let o = Command::new(BIN)
        .args(["synthesize", m, "--weights", "0:0.25", "--out", "full.obj"])
        .current_dir(&d)
        .stdout(std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("error: writing to standard output") && !err.contains("panicked"), "{err}");
    assert!(d.join("full.obj").exists());
    eprintln!("closed stdout cases: {}", cases.len() + 1);
    std::fs::remove_dir_all(&d).unwrap();
}

// ---------------------------------------------------------------------------------------------
// export --fps (item 13)
// ---------------------------------------------------------------------------------------------

#[test]
fn export_fps_is_bounded() {
    let d = fresh_dir("rel-inputs", "fps");
    let model = common::train_cli(&d, "m", "path = \"synthetic:tube\"", "kind = \"pca\"\ncomponents = 2");
    let m = model.to_str().unwrap();
    let bad = ["1e-300", "1e-40", "1e300", "0", "-30", "NaN", "inf", "0.009", "1000.5", "-0"];
    for fps in bad {
        for out in ["x.glb", "x.usda"] {
            let o = meshdeco(&["export", m, "--out", out, "--animation", &format!("--fps={fps}")], &d);
            let text = output_text(&o);
            assert_eq!(o.status.code(), Some(1), "--fps {fps}: {text}");
            assert!(text.contains("--fps") && text.contains("from 0.01 to 1000"), "--fps {fps}: {text}");
            assert!(!text.contains("panicked"));
            assert!(!d.join(out).exists(), "--fps {fps}: {out} written");
        }
    }
    // The message names the value as given (scientific notation for the extremes).
    let o = meshdeco(&["export", m, "--out", "x.glb", "--animation", "--fps", "1e-300"], &d);
    assert!(output_text(&o).contains("--fps 1e-300"), "{}", output_text(&o));
    // The ends of the range: strictly increasing, finite key times.
    for (fps, step) in [("0.01", 100.0), ("1000", 0.001)] {
        let o = meshdeco(&["export", m, "--out", "ok.glb", "--animation", "--fps", fps], &d);
        assert!(o.status.success(), "--fps {fps}: {}", output_text(&o));
        let g = meshdeco::export::read_glb(&d.join("ok.glb")).unwrap();
        assert!(g.times.len() > 1);
        assert!(g.times.iter().all(|t| t.is_finite()));
        assert!(g.times.windows(2).all(|w| w[1] > w[0]), "--fps {fps}: key times not increasing");
        assert!((g.times[1] - step).abs() <= 1e-6 * step, "--fps {fps}: second key at {}", g.times[1]);
    }
    // The library refuses the same values.
    let lm = meshdeco::pipeline::load_model(&model).unwrap();
    for fps in [1e-300, 1e300, f64::NAN, 0.0] {
        let opts = meshdeco::export::ExportOptions { animation: true, fps, ..Default::default() };
        let e = meshdeco::export::export_glb(lm.as_ref(), &d.join("lib.glb"), &opts).unwrap_err().to_string();
        assert!(e.contains("--fps"), "{e}");
    }
    eprintln!("fps cases: {}", 2 * bad.len() + 1 + 2 + 4);
    std::fs::remove_dir_all(&d).unwrap();
}

// ---------------------------------------------------------------------------------------------
// The viewer's HTTP server (item 16)
// ---------------------------------------------------------------------------------------------

/// `http::serve` with `handle` on a free loopback port within `limits`, on its own thread:
/// the address to connect to.
fn serve_with<H>(limits: Limits, handle: H) -> String
where
    H: Fn(&Request) -> Response + Send + Sync + 'static,
{
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    std::thread::spawn(move || http::serve(listener, limits, handle));
    addr
}

/// An echo server on a free loopback port within `limits`: answers the body's length.
fn echo_server(limits: Limits) -> String {
    serve_with(limits, |r: &Request| {
        Response::new(200, "text/plain", format!("{} {} {}", r.method, r.path, r.body.len()).into_bytes())
    })
}

/// Reads what the server sends until it closes (or `limit`): (bytes, time until closed).
fn read_until_closed(s: &mut TcpStream, limit: Duration) -> (Vec<u8>, Duration) {
    let t0 = Instant::now();
    s.set_read_timeout(Some(limit)).unwrap();
    let mut raw = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => raw.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break,
            Err(e) => panic!("still open after {:?}: {e}", t0.elapsed()),
        }
    }
    (raw, t0.elapsed())
}

fn status_of(raw: &[u8]) -> u16 {
    view_support::parse_response(raw).0
}

#[test]
fn http_deadlines_cut_off_slow_clients() {
    let limits = Limits { idle: Duration::from_millis(1500), request: Duration::from_secs(1), ..Limits::default() };
    let addr = echo_server(limits);
    // One byte every 250 ms: each read is quick, the request never completes; cut at 1 s.
    let slow_head = std::thread::spawn({
        let addr = addr.clone();
        move || {
            let mut s = TcpStream::connect(&addr).unwrap();
            let t0 = Instant::now();
            for b in b"GET / HTTP/1.1\r\nHost: x\r\nX: yyyyyyyyyyyyyyyyyyyyyyyy\r\n\r\n" {
                if s.write_all(&[*b]).is_err() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(250));
                if t0.elapsed() > Duration::from_secs(6) {
                    break;
                }
            }
            let (raw, _) = read_until_closed(&mut s, Duration::from_secs(5));
            (raw, t0.elapsed())
        }
    });
    // The head at once, then the body one byte at a time.
    let slow_body = std::thread::spawn({
        let addr = addr.clone();
        move || {
            let mut s = TcpStream::connect(&addr).unwrap();
            let t0 = Instant::now();
            s.write_all(b"POST /x HTTP/1.1\r\nContent-Length: 100\r\n\r\n").unwrap();
            for _ in 0..100 {
                if s.write_all(b"a").is_err() || t0.elapsed() > Duration::from_secs(6) {
                    break;
                }
                std::thread::sleep(Duration::from_millis(100));
            }
            let (raw, _) = read_until_closed(&mut s, Duration::from_secs(5));
            (raw, t0.elapsed())
        }
    });
    // Idle keep-alive: closed after the idle limit, with nothing sent.
    let mut idle = TcpStream::connect(&addr).unwrap();
    let (raw, took) = read_until_closed(&mut idle, Duration::from_secs(6));
    assert!(raw.is_empty() && took >= Duration::from_millis(1000) && took < Duration::from_secs(4), "idle: {took:?}");
    for (what, h) in [("slow head", slow_head), ("slow body", slow_body)] {
        let (raw, took) = h.join().unwrap();
        assert_eq!(status_of(&raw), 408, "{what}: {}", String::from_utf8_lossy(&raw));
        assert!(String::from_utf8_lossy(&raw).contains("did not arrive whole within 1 s"), "{what}");
        assert!(took < Duration::from_secs(4), "{what}: open for {took:?}");
    }
    // A client that does not read a large response is cut off too (write deadline).
    let big = serve_with(limits, |_: &Request| Response::binary(vec![7u8; 64 << 20]));
    let mut s = TcpStream::connect(&big).unwrap();
    s.write_all(b"GET / HTTP/1.1\r\n\r\n").unwrap();
    std::thread::sleep(Duration::from_secs(3));
    // The server gave up: reading now ends well before 64 MiB.
    let (raw, _) = read_until_closed(&mut s, Duration::from_secs(5));
    assert!(raw.len() < 64 << 20, "the whole response was written to a client that did not read");
    // Good requests still work, keep-alive included.
    let (s, _, b) = view_support::http(&addr, "POST", "/ok", b"12345");
    assert_eq!((s, String::from_utf8_lossy(&b).to_string()), (200, "POST /ok 5".to_string()));
    eprintln!("http deadline cases: 5");
}

#[test]
fn http_connections_and_body_bytes_are_capped() {
    let limits = Limits { max_connections: 8, max_body_bytes_in_flight: 1 << 20, ..Limits::default() };
    let addr = serve_with(limits, |r: &Request| {
        if r.path == "/slow" {
            std::thread::sleep(Duration::from_millis(1500));
        }
        Response::new(200, "text/plain", format!("{} {} {}", r.method, r.path, r.body.len()).into_bytes())
    });
    // 8 requests being answered fill the server; 40 more connections are answered 503 at once
    // and closed.
    let held: Vec<_> = (0..8)
        .map(|_| {
            let addr = addr.clone();
            std::thread::spawn(move || view_support::http(&addr, "GET", "/slow", b"").0)
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    for i in 0..40 {
        let mut s = TcpStream::connect(&addr).unwrap();
        let (raw, took) = read_until_closed(&mut s, Duration::from_secs(5));
        assert_eq!(status_of(&raw), 503, "connection {i} over the cap");
        let text = String::from_utf8_lossy(&raw);
        assert!(text.contains("busy: 8 connections are being answered"), "{text}");
        assert!(took < Duration::from_secs(2));
    }
    for h in held {
        assert_eq!(h.join().unwrap(), 200);
    }
    let (s, _, _) = view_support::http(&addr, "GET", "/", b"");
    assert_eq!(s, 200, "served again once the requests were answered");
    // Unfinished bodies: two of 400 KiB fit the 1 MiB budget, the third is answered 503 before
    // its body is read; once they finish, bodies are accepted again.
    let mut open = Vec::new();
    for _ in 0..2 {
        let mut s = TcpStream::connect(&addr).unwrap();
        let head = format!("POST /b HTTP/1.1\r\nContent-Length: {}\r\nConnection: close\r\n\r\n", 400 << 10);
        s.write_all(head.as_bytes()).unwrap();
        s.write_all(&vec![b'x'; 200 << 10]).unwrap();
        open.push(s);
    }
    std::thread::sleep(Duration::from_millis(300));
    let mut third = TcpStream::connect(&addr).unwrap();
    third.write_all(format!("POST /b HTTP/1.1\r\nContent-Length: {}\r\n\r\n", 400 << 10).as_bytes()).unwrap();
    let (raw, _) = read_until_closed(&mut third, Duration::from_secs(5));
    assert_eq!(status_of(&raw), 503, "{}", String::from_utf8_lossy(&raw));
    assert!(String::from_utf8_lossy(&raw).contains("at most 1048576 bytes at once"));
    for mut s in open {
        s.write_all(&vec![b'x'; 200 << 10]).unwrap();
        let (raw, _) = read_until_closed(&mut s, Duration::from_secs(5));
        let text = String::from_utf8_lossy(&raw);
        assert!(text.contains(&format!("POST /b {}", 400 << 10)), "{text}");
    }
    let (s, _, b) = view_support::http(&addr, "POST", "/after", &vec![b'y'; 500 << 10]);
    assert_eq!(s, 200, "{}", String::from_utf8_lossy(&b));
    eprintln!("http cap cases: {}", 40 + 5);
}

#[test]
fn http_duplicate_or_malformed_content_length_is_400() {
    let addr = echo_server(Limits::default());
    let cases: [(&str, u16, &str); 7] = [
        ("Content-Length: 3\r\nContent-Length: 3\r\n", 400, "duplicate Content-Length"),
        ("Content-Length: 3\r\nContent-Length: 5\r\n", 400, "duplicate Content-Length"),
        ("content-length: 3\r\nCONTENT-LENGTH: 3\r\n", 400, "duplicate Content-Length"),
        ("Content-Length: +3\r\n", 400, "`+3` is not a number"),
        ("Content-Length: 3 3\r\n", 400, "not a number"),
        ("Content-Length: -1\r\n", 400, "not a number"),
        ("Content-Length: 3\r\n", 200, "POST /d 3"),
    ];
    for (headers, status, needle) in cases {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.write_all(format!("POST /d HTTP/1.1\r\n{headers}Connection: close\r\n\r\nabc").as_bytes()).unwrap();
        let (raw, _) = read_until_closed(&mut s, Duration::from_secs(5));
        let text = String::from_utf8_lossy(&raw);
        assert_eq!(status_of(&raw), status, "{headers:?}: {text}");
        assert!(text.contains(needle), "{headers:?}: {text}");
    }
    eprintln!("http content-length cases: {}", cases.len());
}

/// VmRSS (kB) and thread count of process `pid`.
fn rss_and_threads(pid: u32) -> (u64, u64) {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let field = |name: &str| -> u64 {
        s.lines()
            .find_map(|l| l.strip_prefix(name))
            .map(|v| v.trim().trim_end_matches("kB").trim().parse().unwrap())
            .unwrap()
    };
    (field("VmRSS:"), field("Threads:"))
}

#[test]
fn viewer_binary_caps_connections_memory_and_duplicate_headers() {
    let d = fresh_dir("rel-inputs", "viewer");
    let model = view_support::train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 3");
    let v = view_support::Viewer::start(&[model.to_str().unwrap()]);
    let pid = v.child.id();
    // Duplicate Content-Length: 400, and the server keeps serving.
    let mut s = TcpStream::connect(&v.addr).unwrap();
    s.write_all(b"POST /api/decode HTTP/1.1\r\nContent-Length: 2\r\nContent-Length: 2\r\n\r\n{}").unwrap();
    let (raw, _) = read_until_closed(&mut s, Duration::from_secs(10));
    assert_eq!(status_of(&raw), 400, "{}", String::from_utf8_lossy(&raw));
    assert_eq!(v.request("GET", "/api/model", b"").0, 200);
    // 50 unfinished 4 MiB bodies (3 MiB sent of each): memory stays within the body budget.
    let (rss0, _) = rss_and_threads(pid);
    let mut bodies = Vec::new();
    let mut refused = 0;
    for _ in 0..50 {
        let mut s = TcpStream::connect(&v.addr).unwrap();
        let head = format!("POST /api/decode HTTP/1.1\r\nContent-Length: {}\r\n\r\n", http::MAX_BODY);
        s.set_write_timeout(Some(Duration::from_secs(2))).unwrap();
        let sent = s.write_all(head.as_bytes()).is_ok() && s.write_all(&vec![b' '; 3 << 20]).is_ok();
        // A body that was taken in gets no answer yet; a refused one a 503 (or a reset).
        s.set_read_timeout(Some(Duration::from_millis(200))).unwrap();
        let mut b = [0u8; 64];
        let waiting = match s.read(&mut b) {
            Ok(n) => {
                assert!(n == 0 || String::from_utf8_lossy(&b[..n]).contains("503"), "{}", String::from_utf8_lossy(&b));
                false
            }
            Err(e) => matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut),
        };
        if !sent || !waiting {
            refused += 1;
        }
        bodies.push(s);
    }
    std::thread::sleep(Duration::from_millis(500));
    let (rss1, threads) = rss_and_threads(pid);
    let grown_mb = rss1.saturating_sub(rss0) / 1024;
    assert!(grown_mb < 40, "50 unfinished bodies grew the viewer by {grown_mb} MB");
    let taken = 50 - refused;
    assert!(
        taken <= http::MAX_BODY_BYTES_IN_FLIGHT / http::MAX_BODY,
        "{taken} unfinished 4 MiB bodies taken in at once (budget {} bytes)",
        http::MAX_BODY_BYTES_IN_FLIGHT
    );
    drop(bodies);
    // 200 idle connections: at most MAX_CONNECTIONS held (threads bounded; each new one closes
    // the oldest that has sent nothing), and the page's own requests are answered meanwhile.
    let mut idle = Vec::new();
    for _ in 0..200 {
        idle.push(TcpStream::connect(&v.addr).unwrap());
    }
    std::thread::sleep(Duration::from_millis(300));
    let (_, threads_idle) = rss_and_threads(pid);
    assert!(
        threads_idle <= threads.max(8) + http::MAX_CONNECTIONS as u64 + 4,
        "{threads_idle} threads with 200 idle connections"
    );
    let t0 = Instant::now();
    assert_eq!(v.request("GET", "/api/model", b"").0, 200, "the page is answered beside 200 idle connections");
    assert!(t0.elapsed() < Duration::from_secs(5), "answered after {:?}", t0.elapsed());
    let mut closed = 0;
    for s in &mut idle {
        s.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        if matches!(s.read(&mut [0u8; 64]), Ok(0)) {
            closed += 1;
        }
    }
    assert!(closed >= 200 - http::MAX_CONNECTIONS, "only {closed} of 200 idle connections were closed");
    drop(idle);
    eprintln!("viewer binary cases: 5");
    drop(v);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn viewer_binary_cuts_off_a_one_byte_every_few_seconds_client() {
    let d = fresh_dir("rel-inputs", "viewer-slow");
    let model = view_support::train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 2");
    let v = view_support::Viewer::start(&[model.to_str().unwrap()]);
    let mut s = TcpStream::connect(&v.addr).unwrap();
    let t0 = Instant::now();
    let mut closed = false;
    // One byte every 2 s of a head that never ends: cut at REQUEST_TIME (30 s), not kept open.
    while t0.elapsed() < http::REQUEST_TIME + Duration::from_secs(10) {
        if s.write_all(b"G").is_err() {
            closed = true;
            break;
        }
        s.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let mut b = [0u8; 512];
        match s.read(&mut b) {
            Ok(0) => {
                closed = true;
                break;
            }
            Ok(n) => {
                assert!(String::from_utf8_lossy(&b[..n]).contains("408"), "{}", String::from_utf8_lossy(&b[..n]));
                closed = true;
                break;
            }
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => {
                closed = true;
                break;
            }
        }
    }
    let took = t0.elapsed();
    assert!(closed, "the slow client is still connected after {took:?}");
    assert!(took < http::REQUEST_TIME + Duration::from_secs(5), "closed after {took:?}");
    eprintln!("viewer slow-client cases: 1");
    drop(v);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn viewer_host_names_and_ipv6() {
    let d = fresh_dir("rel-inputs", "viewer-host");
    let model = view_support::train(&d, "pca", "synthetic:tube", "kind = \"pca\"\ncomponents = 2");
    let m = model.to_str().unwrap();
    let mut n = 0;
    // `localhost` is accepted and served on 127.0.0.1.
    let v = view_support::Viewer::start(&[m, "--host", "localhost"]);
    assert!(v.banner.contains("serving http://127.0.0.1:"), "{}", v.banner);
    assert_eq!(v.request("GET", "/api/model", b"").0, 200);
    drop(v);
    n += 1;
    // `::` (every address, IPv6): the URL is [::1] (bracketed, openable), the listening
    // address [::]:PORT; where this machine has no IPv6 the refusal names --host.
    let ipv6 = TcpListener::bind("[::1]:0").is_ok();
    if ipv6 {
        for host in ["::", "[::1]", "::1"] {
            let v = view_support::Viewer::start(&[m, "--host", host]);
            assert!(v.banner.contains("serving http://[::1]:"), "--host {host}: {}", v.banner);
            assert!(!v.banner.contains("[127.0.0.1]"), "{}", v.banner);
            if host == "::" {
                assert!(v.banner.contains("[::]:"), "{}", v.banner);
            }
            assert_eq!(v.request("GET", "/api/model", b"").0, 200, "--host {host}");
            n += 1;
        }
    } else {
        eprintln!("no IPv6 loopback here: --host :: checked for a clear refusal only");
        let r = run_bounded(&["view", m, "--host", "::", "--port", "0"], &d, Duration::from_secs(20));
        assert_refused("--host :: without IPv6", &r, &["--host"]);
        n += 1;
    }
    // Not an address or a name: refused naming the flag, nothing served.
    for host in ["not a host", "1.2.3.4.5/8", ""] {
        let r = run_bounded(&["view", m, "--host", host, "--port", "0"], &d, Duration::from_secs(20));
        assert_refused(&format!("--host {host:?}"), &r, &["--host"]);
        n += 1;
    }
    eprintln!("viewer host cases: {n}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// What README.md and docs/viewer.md promise of request heads and bodies on the default limits:
/// a 16 KiB head is read and one byte more is a 431; a 4 MiB body is read and one byte more is a
/// 413; four 4 MiB bodies (16 MiB) are received at once and a fifth is a 503 until they end;
/// chunked bodies are a 411 and a malformed request line a 400. Blank lines before a request are
/// skipped, bare `\n` line ends read, the query string split off the path, and an HTTP/1.0
/// connection closed after one response unless it asks for keep-alive.
#[test]
fn http_heads_bodies_and_connections_on_the_default_limits() {
    let addr = echo_server(Limits::default());
    let exchange = |raw: &[u8]| -> String {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.write_all(raw).unwrap();
        String::from_utf8_lossy(&read_until_closed(&mut s, Duration::from_secs(10)).0).into_owned()
    };
    let status_line = |t: &str| t.lines().next().unwrap_or_default().to_string();
    let mut n = 0;
    // Heads: exactly 16 KiB is read; one byte more is refused (and nothing past it is read).
    let head = |len: usize| {
        let frame = "GET /h HTTP/1.1\r\nConnection: close\r\nX: \r\n\r\n".len();
        format!("GET /h HTTP/1.1\r\nConnection: close\r\nX: {}\r\n\r\n", "y".repeat(len - frame))
    };
    assert_eq!(head(16 << 10).len(), 16 << 10);
    let t = exchange(head(16 << 10).as_bytes());
    assert!(status_of(t.as_bytes()) == 200 && t.ends_with("GET /h 0"), "{t}");
    let t = exchange(head((16 << 10) + 1).as_bytes());
    assert_eq!(status_of(t.as_bytes()), 431, "{t}");
    assert!(t.contains("request head longer than 16384 bytes"), "{t}");
    // A head whose last line runs past 16 KiB without a line end is refused as soon as its
    // 16 385th byte arrives, without waiting for more (the client sends nothing after it).
    let start = "GET /h HTTP/1.1\r\nConnection: close\r\nX: ";
    let t = exchange(format!("{start}{}", "y".repeat((16 << 10) + 1 - start.len())).as_bytes());
    assert_eq!(status_of(t.as_bytes()), 431, "{t}");
    n += 3;
    // Bodies: 4 MiB is read whole; a Content-Length one byte over is refused from the head.
    let mut raw = format!("POST /b HTTP/1.1\r\nContent-Length: {}\r\nConnection: close\r\n\r\n", 4 << 20).into_bytes();
    raw.resize(raw.len() + (4 << 20), b'z');
    let t = exchange(&raw);
    assert!(status_of(t.as_bytes()) == 200 && t.ends_with(&format!("POST /b {}", 4 << 20)), "{}", status_line(&t));
    let t = exchange(format!("POST /b HTTP/1.1\r\nContent-Length: {}\r\n\r\n", (4 << 20) + 1).as_bytes());
    assert_eq!(status_of(t.as_bytes()), 413, "{t}");
    assert!(t.contains("larger than the limit of 4194304"), "{t}");
    n += 2;
    // Four unfinished 4 MiB bodies are all taken in (16 MiB at once); a fifth is a 503.
    let mut open = Vec::new();
    for i in 0..4 {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.write_all(format!("POST /u HTTP/1.1\r\nContent-Length: {}\r\n\r\n", 4 << 20).as_bytes()).unwrap();
        s.write_all(&[b'u'; 1024]).unwrap();
        s.set_read_timeout(Some(Duration::from_millis(300))).unwrap();
        let mut b = [0u8; 256];
        match s.read(&mut b) {
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            other => panic!("unfinished body {i} of 4 was not taken in: {other:?} {}", String::from_utf8_lossy(&b)),
        }
        open.push(s);
    }
    let t = exchange(format!("POST /u HTTP/1.1\r\nContent-Length: {}\r\n\r\n", 4 << 20).as_bytes());
    assert_eq!(status_of(t.as_bytes()), 503, "{t}");
    assert!(t.contains("at most 16777216 bytes at once") && t.contains("Retry-After: 1\r\n"), "{t}");
    // Once those connections end, their reservations are given back.
    drop(open);
    std::thread::sleep(Duration::from_millis(500));
    let (s, _, b) = view_support::http(&addr, "POST", "/after", b"abc");
    assert_eq!((s, String::from_utf8_lossy(&b).to_string()), (200, "POST /after 3".to_string()));
    n += 3;
    // Request lines and headers.
    let cases: [(&[u8], u16, &str); 5] = [
        (b"POST /c HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n", 411, "send Content-Length"),
        (b"GARBAGE\r\n\r\n", 400, "malformed request line `GARBAGE`"),
        (b"\r\n\r\nGET /s HTTP/1.1\r\nConnection: close\r\n\r\n", 200, "GET /s 0"),
        (b"GET /n HTTP/1.1\nConnection: close\n\n", 200, "GET /n 0"),
        (b"GET /q?a=1&b=%3F HTTP/1.1\r\nConnection: close\r\n\r\n", 200, "GET /q 0"),
    ];
    for (raw, status, tail) in cases {
        let t = exchange(raw);
        assert_eq!(status_of(t.as_bytes()), status, "{}: {t}", String::from_utf8_lossy(raw));
        assert!(t.ends_with(&format!("{tail}\"}}")) || t.ends_with(tail), "{}: {t}", String::from_utf8_lossy(raw));
        n += 1;
    }
    // HTTP/1.0 closes after its response (the 10 s limit would fail on an open connection) ...
    let t = exchange(b"GET /a HTTP/1.0\r\n\r\n");
    assert!(t.contains("Connection: close\r\n") && t.ends_with("GET /a 0"), "{t}");
    // ... unless it asks for keep-alive; HTTP/1.1 keeps the connection unless told to close.
    let t = exchange(b"GET /a HTTP/1.0\r\nConnection: keep-alive\r\n\r\nGET /b HTTP/1.0\r\n\r\n");
    assert_eq!(t.matches("HTTP/1.1 200 OK\r\n").count(), 2, "{t}");
    assert!(t.contains("Connection: keep-alive\r\n") && t.ends_with("GET /b 0"), "{t}");
    let t = exchange(b"GET /a HTTP/1.1\r\n\r\nGET /b HTTP/1.1\r\nConnection: Close\r\n\r\n");
    assert_eq!(t.matches("HTTP/1.1 200 OK\r\n").count(), 2, "{t}");
    n += 3;
    // `Expect: 100-continue` on an empty body: there is nothing to wait for, so the final
    // response is the first and only one (no interim 100).
    let t = exchange(b"POST /e HTTP/1.1\r\nContent-Length: 0\r\nExpect: 100-continue\r\nConnection: close\r\n\r\n");
    assert!(t.starts_with("HTTP/1.1 200 OK\r\n") && !t.contains("100 Continue") && t.ends_with("POST /e 0"), "{t}");
    // A client that half-closes before its whole body arrived: the request is dropped, not
    // answered as if the shorter body were all of it (the echo would say `POST /cut 5`).
    let mut s = TcpStream::connect(&addr).unwrap();
    s.write_all(b"POST /cut HTTP/1.1\r\nContent-Length: 10\r\n\r\n12345").unwrap();
    s.shutdown(std::net::Shutdown::Write).unwrap();
    let (raw, took) = read_until_closed(&mut s, Duration::from_secs(10));
    assert!(raw.is_empty(), "a cut-short body was answered: {}", String::from_utf8_lossy(&raw));
    assert!(took < Duration::from_secs(5), "the connection stayed open {took:?} after the client's half-close");
    n += 2;
    eprintln!("http head and body cases: {n}");
}

#[test]
fn http_a_client_that_hangs_up_mid_response_frees_its_connection_at_once() {
    // One connection at most, and 8 s to write a response: a server that kept writing to a
    // client that is gone would hold the only slot for those 8 s.
    let limits = Limits { max_connections: 1, request: Duration::from_secs(8), ..Limits::default() };
    let addr = serve_with(limits, |r: &Request| match r.path.as_str() {
        "/big" => Response::binary(vec![7u8; 64 << 20]),
        _ => Response::new(200, "text/plain", b"small".to_vec()),
    });
    let mut s = TcpStream::connect(&addr).unwrap();
    s.write_all(b"GET /big HTTP/1.1\r\n\r\n").unwrap();
    let mut start = [0u8; 4096];
    s.read_exact(&mut start).unwrap();
    assert!(start.starts_with(b"HTTP/1.1 200 OK\r\n"));
    // Closing with unread bytes resets the connection: the server's next write fails.
    drop(s);
    let t0 = Instant::now();
    let mut busy = 0;
    loop {
        let (status, _, body) = view_support::http(&addr, "GET", "/small", b"");
        if status == 200 {
            assert_eq!(body, b"small");
            break;
        }
        assert_eq!(status, 503, "{}", String::from_utf8_lossy(&body));
        busy += 1;
        assert!(
            t0.elapsed() < Duration::from_secs(4),
            "the connection of a client that hung up was held {:?} ({busy} requests answered 503)",
            t0.elapsed()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    eprintln!("slot free {:?} after the client hung up ({busy} requests answered 503 before)", t0.elapsed());
}

#[test]
fn http_every_status_the_viewer_sends_has_its_reason_phrase() {
    // The status line as a client reads it, for every status the viewer and its HTTP layer
    // answer with (a 500 is a model call that panicked).
    let statuses = [
        (200, "OK"),
        (400, "Bad Request"),
        (404, "Not Found"),
        (405, "Method Not Allowed"),
        (408, "Request Timeout"),
        (409, "Conflict"),
        (411, "Length Required"),
        (413, "Payload Too Large"),
        (431, "Request Header Fields Too Large"),
        (500, "Internal Server Error"),
        (503, "Service Unavailable"),
    ];
    let addr = serve_with(Limits::default(), |r: &Request| {
        Response::error(r.path.trim_start_matches('/').parse().unwrap_or(404), "as asked")
    });
    for (status, phrase) in statuses {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.write_all(format!("GET /{status} HTTP/1.1\r\nConnection: close\r\n\r\n").as_bytes()).unwrap();
        let (raw, _) = read_until_closed(&mut s, Duration::from_secs(10));
        let text = String::from_utf8_lossy(&raw);
        assert!(text.starts_with(&format!("HTTP/1.1 {status} {phrase}\r\n")), "{text}");
    }
    eprintln!("http reason phrases: {}", statuses.len());
}

/// A signal that interrupts the server's blocked write (`EINTR`: a socket with a send timeout
/// is never restarted, whatever `SA_RESTART` says) does not cut the response: the write is
/// tried again. A client asks for 64 MiB and reads nothing for a while, so the server's write
/// blocks; the connection's thread then gets twenty `SIGUSR1`s (a handler that does nothing);
/// afterwards the client reads the whole body.
#[cfg(target_os = "linux")]
#[test]
fn http_a_signal_during_a_blocked_write_does_not_cut_the_response() {
    use std::sync::atomic::{AtomicI32, Ordering};
    static WRITER: AtomicI32 = AtomicI32::new(0);
    extern "C" fn nothing(_: libc::c_int) {}
    // SAFETY: installs a handler that does nothing for a signal nothing else in this process
    // uses; the struct is zeroed and then filled as sigaction(2) describes.
    unsafe {
        let mut action: libc::sigaction = std::mem::zeroed();
        action.sa_sigaction = nothing as extern "C" fn(libc::c_int) as libc::sighandler_t;
        action.sa_flags = libc::SA_RESTART;
        libc::sigemptyset(&mut action.sa_mask);
        assert_eq!(libc::sigaction(libc::SIGUSR1, &action, std::ptr::null_mut()), 0);
    }
    const SIZE: usize = 64 << 20;
    // Not every signal finds the write blocked with nothing sent (some end a write early with
    // a short count instead): 20 make an `EINTR` all but certain.
    const SIGNALS: usize = 20;
    let limits = Limits { request: Duration::from_secs(30), ..Limits::default() };
    let addr = serve_with(limits, |_: &Request| {
        // SAFETY: gettid has no preconditions.
        WRITER.store(unsafe { libc::gettid() }, Ordering::SeqCst);
        Response::binary(vec![7u8; SIZE])
    });
    let mut s = TcpStream::connect(&addr).unwrap();
    s.write_all(b"GET /big HTTP/1.1\r\nConnection: close\r\n\r\n").unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let tid = WRITER.load(Ordering::SeqCst);
    assert!(tid > 0, "the request was not answered within 0.5 s");
    // A thread that gave up on the connection is gone, and the next signal finds no thread.
    let mut sent = 0;
    for _ in 0..SIGNALS {
        // SAFETY: sends SIGUSR1 (handled above, doing nothing) to the server's connection thread.
        if unsafe { libc::syscall(libc::SYS_tgkill, libc::getpid(), tid, libc::SIGUSR1) } != 0 {
            break;
        }
        sent += 1;
        std::thread::sleep(Duration::from_millis(50));
    }
    let (raw, took) = read_until_closed(&mut s, Duration::from_secs(30));
    let (status, _, body) = view_support::parse_response(&raw);
    assert_eq!(status, 200);
    assert_eq!(body.len(), SIZE, "the response was cut after {sent} signal(s) (read for {took:?})");
    assert_eq!(sent, SIGNALS, "the writing thread ended while the response was being written");
    eprintln!("64 MiB read whole after {sent} signals to the writing thread, in {took:?}");
}

/// Issue 55, cause 5: connections that have not sent a whole request cannot hold the viewer's
/// slots. With every slot held by connections that send nothing (or half a request), a new
/// request is answered at once and the connection that waited longest without a request is
/// closed (before: every other request got 503 for the 120 s idle limit); a connection that has
/// been answered and waits for its next request is closed only after those; a connection whose
/// first request has not arrived whole within `first_request` is closed even when nobody else
/// waits (408 for half a request).
#[test]
fn http_idle_connections_cannot_lock_out_the_page() {
    let limits = Limits { max_connections: 8, ..Limits::default() };
    let addr = echo_server(limits);
    let mut n = 0;
    // A keep-alive connection that has been answered, then 4 silent ones and 3 with half a head.
    // A keep-alive request on `s`: its answer, read until the echo of `path`.
    let ask = |s: &mut TcpStream, path: &str| -> Vec<u8> {
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        s.write_all(format!("GET {path} HTTP/1.1\r\n\r\n").as_bytes()).unwrap();
        let (mut raw, mut buf) = (Vec::new(), [0u8; 256]);
        while !raw.ends_with(format!("GET {path} 0").as_bytes()) {
            let got = s.read(&mut buf).unwrap();
            assert!(got > 0, "{path}: closed after {}", String::from_utf8_lossy(&raw));
            raw.extend_from_slice(&buf[..got]);
        }
        raw
    };
    let mut kept = TcpStream::connect(&addr).unwrap();
    assert_eq!(status_of(&ask(&mut kept, "/first")), 200);
    let mut silent: Vec<TcpStream> = (0..4).map(|_| TcpStream::connect(&addr).unwrap()).collect();
    for _ in 0..3 {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.write_all(b"GET /half HTTP/1.1\r\nX: ").unwrap();
        silent.push(s);
    }
    std::thread::sleep(Duration::from_millis(300));
    // Every slot is held: 7 new keep-alive requests (their connections stay open) are answered
    // at once, each closing the connection that has waited longest without a whole request.
    let mut pages = Vec::new();
    for (i, waiting) in silent.iter_mut().enumerate().take(7) {
        let t0 = Instant::now();
        let mut page = TcpStream::connect(&addr).unwrap();
        assert_eq!(status_of(&ask(&mut page, "/page")), 200, "request {i}");
        assert!(t0.elapsed() < Duration::from_secs(1), "request {i} waited {:?}", t0.elapsed());
        let (raw, _) = read_until_closed(waiting, Duration::from_secs(1));
        assert!(raw.is_empty(), "connection {i} was closed without an answer: {}", String::from_utf8_lossy(&raw));
        pages.push(page);
        n += 1;
    }
    // The connection that had been answered is still open and is answered again.
    assert_eq!(status_of(&ask(&mut kept, "/again")), 200);
    n += 1;
    // Alone on the server: nothing sent, closed after `first_request`; half a head, 408.
    let addr = echo_server(Limits { first_request: Duration::from_secs(2), ..limits });
    let mut s = TcpStream::connect(&addr).unwrap();
    let (raw, took) = read_until_closed(&mut s, Duration::from_secs(6));
    assert!(raw.is_empty() && took >= Duration::from_millis(1500) && took < Duration::from_secs(4), "{took:?}");
    let mut s = TcpStream::connect(&addr).unwrap();
    s.write_all(b"GET /half HTTP/1.1\r\n").unwrap();
    let (raw, took) = read_until_closed(&mut s, Duration::from_secs(6));
    assert_eq!(status_of(&raw), 408, "{}", String::from_utf8_lossy(&raw));
    assert!(String::from_utf8_lossy(&raw).contains("within 2 s of connecting"), "{}", String::from_utf8_lossy(&raw));
    assert!(took < Duration::from_secs(4), "{took:?}");
    n += 2;
    eprintln!("http idle-connection cases: {n}");
}
