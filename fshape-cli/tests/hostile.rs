//! Files a careless script or a hostile colleague could produce: devices,
//! FIFOs, short files, offsets past the end, huge counts, decompression
//! bombs, runaway signal tables. Each is given to a child `fshape` under a
//! CPU-time limit of 1 s and an address-space limit of 64 MiB above what
//! reading a small valid file needs (so memory growth past 64 MiB aborts
//! the child, which the test sees); each must end in a clean error (exit
//! status 1, `error: …` naming the problem), within a wall-clock watchdog
//! that catches a blocked read. The corpus is made here, in a temporary
//! folder, on each run.
#![cfg(target_os = "linux")]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Memory a hostile file may add to a small file's reading.
const GROWTH_KIB: u64 = 64 << 10;

struct Outcome {
    code: Option<i32>,
    stderr: String,
    wall: Duration,
}

/// Runs `fshape args…` (through `sh -c`, with `shell_prefix` before it,
/// e.g. a pipe) under `ulimit -v limit_kib` and 1 s of CPU; kills it after
/// 20 s of wall time.
fn run_limited(limit_kib: u64, shell_prefix: &str, args: &[&str]) -> Outcome {
    let script = format!("ulimit -v {limit_kib}; ulimit -t 1; {shell_prefix} \"$0\" \"$@\"");
    let start = Instant::now();
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(script)
        .arg(env!("CARGO_BIN_EXE_fshape"))
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("sh runs");
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut stderr = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut stderr).unwrap();
            return Outcome { code: status.code(), stderr, wall: start.elapsed() };
        }
        if start.elapsed() > Duration::from_secs(20) {
            child.kill().unwrap();
            child.wait().unwrap();
            panic!("fshape {args:?} did not finish in 20 s (a blocked read?)");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The smallest address space (KiB, to 1 MiB) in which `fshape info` reads
/// a small valid file.
fn baseline_kib(small: &Path) -> u64 {
    let ok = |kib: u64| run_limited(kib, "exec", &["info", small.to_str().unwrap()]).code == Some(0);
    let (mut lo, mut hi) = (16 << 10, 4 << 20);
    assert!(ok(hi), "fshape info of a small file fails even with 4 GiB");
    while hi - lo > 1 << 10 {
        let mid = (lo + hi) / 2;
        if ok(mid) { hi = mid } else { lo = mid }
    }
    hi
}

fn gifti_external(dir: &Path, file: &str, name: &str, dim: u64, offset: u64) -> PathBuf {
    let path = dir.join(file);
    let xml = format!(
        "<?xml version=\"1.0\"?>\n<GIFTI Version=\"1.0\" NumberOfDataArrays=\"1\">\n\
         <DataArray Intent=\"NIFTI_INTENT_SHAPE\" DataType=\"NIFTI_TYPE_FLOAT32\" ArrayIndexingOrder=\"RowMajorOrder\" \
         Dimensionality=\"1\" Dim0=\"{dim}\" Encoding=\"ExternalFileBinary\" Endian=\"LittleEndian\" \
         ExternalFileName=\"{name}\" ExternalFileOffset=\"{offset}\"><Data></Data></DataArray>\n</GIFTI>\n"
    );
    std::fs::write(&path, xml).unwrap();
    path
}

fn gz(path: &Path, parts: &[(&[u8], usize)]) {
    let file = std::fs::File::create(path).unwrap();
    // A bomb is small: the best compression (about 1000 times on repeated bytes).
    let mut enc = flate2::write::GzEncoder::new(std::io::BufWriter::new(file), flate2::Compression::best());
    for (chunk, times) in parts {
        for _ in 0..*times {
            enc.write_all(chunk).unwrap();
        }
    }
    enc.finish().unwrap().flush().unwrap();
}

/// A little-endian CIFTI-2 file: a NIfTI-2 header with matrix dimensions
/// `lens` of float32, the XML extension, then `data`.
fn cifti(xml: &str, lens: [i64; 2], data: &[u8]) -> Vec<u8> {
    let mut h = vec![0u8; 540];
    h[..4].copy_from_slice(&540i32.to_le_bytes());
    h[4..12].copy_from_slice(b"n+2\0\r\n\x1a\n");
    h[12..14].copy_from_slice(&16i16.to_le_bytes());
    for (k, d) in [6, 1, 1, 1, 1, lens[0], lens[1], 1].into_iter().enumerate() {
        h[16 + 8 * k..24 + 8 * k].copy_from_slice(&i64::to_le_bytes(d));
    }
    let esize = (8 + xml.len()).div_ceil(16) * 16;
    h[168..176].copy_from_slice(&((544 + esize) as i64).to_le_bytes());
    h.extend([1, 0, 0, 0]);
    h.extend((esize as i32).to_le_bytes());
    h.extend(32i32.to_le_bytes());
    h.extend(xml.as_bytes());
    h.resize(544 + esize, 0);
    h.extend(data);
    h
}

#[test]
fn hostile_files_end_in_clean_errors_within_bounded_time_and_memory() {
    let dir = std::env::temp_dir().join(format!("fshape-hostile-{}", std::process::id()));
    let sub = dir.join("surfaces");
    std::fs::create_dir_all(&sub).unwrap();
    let p = |name: &str| sub.join(name).to_str().unwrap().to_string();

    // A small valid surface (a tetrahedron) and its signal.
    let small = sub.join("small.ply");
    std::fs::write(
        &small,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
         element face 4\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
    )
    .unwrap();
    let base = baseline_kib(&small);
    let limit = base + GROWTH_KIB;

    // Devices, FIFOs and folders, named directly or through a link.
    std::os::unix::fs::symlink("/dev/zero", sub.join("zero.ply")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", sub.join("zero.bin")).unwrap();
    std::os::unix::fs::symlink("/dev/urandom", sub.join("random.bin")).unwrap();
    for fifo in ["fifo.bin", "fifo.dlabel.nii"] {
        assert!(Command::new("mkfifo").arg(sub.join(fifo)).status().unwrap().success(), "mkfifo");
    }
    std::fs::create_dir_all(sub.join("folder.ply")).unwrap();
    // External GIfTI data: outside the folder, a device, a FIFO, too short, an offset past the end.
    gifti_external(&sub, "abs_zero.shape.gii", "/dev/zero", 1_000_000_000, 0);
    gifti_external(&sub, "up.shape.gii", "../outside.bin", 4, 0);
    std::fs::write(dir.join("outside.bin"), [0u8; 16]).unwrap();
    gifti_external(&sub, "link_zero.shape.gii", "zero.bin", 1_000_000_000, 0);
    gifti_external(&sub, "link_random.shape.gii", "random.bin", 1_000_000_000, 0);
    gifti_external(&sub, "fifo.shape.gii", "fifo.bin", 4, 0);
    std::fs::write(sub.join("short.bin"), [0u8; 100]).unwrap();
    gifti_external(&sub, "short.shape.gii", "short.bin", 1_000_000_000, 0);
    gifti_external(&sub, "offset.shape.gii", "short.bin", 4, 1 << 40);
    gifti_external(&sub, "huge_dim.shape.gii", "short.bin", 1 << 40, 0);
    // Headers that claim more than the file holds, or more than the limit.
    std::fs::write(
        sub.join("huge_count.ply"),
        "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n\
         property float z\nend_header\n",
    )
    .unwrap();
    let mut curv = vec![0xff, 0xff, 0xff];
    curv.extend(0x7fff_ffffi32.to_be_bytes());
    curv.extend(1i32.to_be_bytes());
    curv.extend(1i32.to_be_bytes());
    std::fs::write(sub.join("lh.thickness"), &curv).unwrap();
    // Decompression bombs behind a valid start: a PLY header then 64 MiB
    // of spaces; a signal column of 100 M values for a 4-vertex mesh.
    gz(
        &sub.join("bomb.ply.gz"),
        &[(b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nend_header\n", 1), (&[b' '; 1 << 20], 64)],
    );
    let ones = b"1\n".repeat(1 << 19);
    gz(&sub.join("bomb.csv.gz"), &[(b"thickness\n", 1), (&ones, 200)]);
    // An uncompressed runaway signal table: 64 MB of values for 4 vertices.
    let mut big = std::io::BufWriter::new(std::fs::File::create(sub.join("runaway.csv")).unwrap());
    big.write_all(b"thickness\n").unwrap();
    for _ in 0..64 {
        big.write_all(&ones).unwrap();
    }
    big.into_inner().unwrap().sync_all().unwrap();

    // A CIFTI-2 file whose structure claims 2·10⁹ surface vertices, one
    // whose matrix claims 10⁹ × 10⁹ values, and an annotation claiming
    // 2³¹ − 1 vertices.
    let xml = |surface: u64| {
        format!(
            "<CIFTI Version=\"2\"><Matrix><MatrixIndicesMap AppliesToMatrixDimension=\"0\" \
             IndicesMapToDataType=\"CIFTI_INDEX_TYPE_SCALARS\"><NamedMap><MapName>t</MapName></NamedMap>\
             </MatrixIndicesMap><MatrixIndicesMap AppliesToMatrixDimension=\"1\" \
             IndicesMapToDataType=\"CIFTI_INDEX_TYPE_BRAIN_MODELS\"><BrainModel IndexOffset=\"0\" \
             IndexCount=\"2\" ModelType=\"CIFTI_MODEL_TYPE_SURFACE\" BrainStructure=\"CIFTI_STRUCTURE_CORTEX_LEFT\" \
             SurfaceNumberOfVertices=\"{surface}\"><VertexIndices>0 1</VertexIndices></BrainModel>\
             </MatrixIndicesMap></Matrix></CIFTI>"
        )
    };
    std::fs::write(sub.join("huge_surface.dscalar.nii"), cifti(&xml(2_000_000_000), [1, 2], &[0u8; 8])).unwrap();
    std::fs::write(sub.join("huge_matrix.dscalar.nii"), cifti(&xml(4), [1_000_000_000, 1_000_000_000], &[])).unwrap();
    let mut annot = 0x7fff_ffffi32.to_be_bytes().to_vec();
    annot.extend([0u8; 64]);
    std::fs::write(sub.join("lh.huge.annot"), &annot).unwrap();
    std::os::unix::fs::symlink("/dev/zero", sub.join("lh.zero.annot")).unwrap();
    // Run records: a folder whose summary.json or index.json is a FIFO, a
    // device or a nesting bomb.
    for (run, file) in [("fifo_run", "summary.json"), ("fifo_batch", "index.json")] {
        std::fs::create_dir_all(sub.join(run)).unwrap();
        assert!(Command::new("mkfifo").arg(sub.join(run).join(file)).status().unwrap().success(), "mkfifo");
    }
    std::fs::create_dir_all(sub.join("zero_run")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", sub.join("zero_run/summary.json")).unwrap();
    std::fs::create_dir_all(sub.join("nested_run")).unwrap();
    std::fs::write(sub.join("nested_run/summary.json"), "[".repeat(1 << 20)).unwrap();

    let small_s = small.to_str().unwrap();
    // `fshape info SMALL --signal FILE`: the hostile file as a signal.
    let signal = |file: &str| vec!["info".to_string(), small_s.into(), "--signal".into(), file.into()];
    let mask = |file: &str| vec!["info".to_string(), small_s.into(), "--mask".into(), file.into()];
    let cases: Vec<(&str, Vec<String>, &str)> = vec![
        ("exec", vec!["info".into(), "/dev/zero".into()], "device"),
        ("exec", vec!["info".into(), p("zero.ply")], "device"),
        ("exec", vec!["info".into(), p("folder.ply")], "folder"),
        ("exec", signal(&p("zero.bin")), "device"),
        ("exec", signal(&p("abs_zero.shape.gii")), "outside the .gii's folder"),
        ("exec", signal(&p("up.shape.gii")), "outside the .gii's folder"),
        ("exec", signal(&p("link_zero.shape.gii")), "not a regular file"),
        ("exec", signal(&p("link_random.shape.gii")), "not a regular file"),
        ("exec", signal(&p("fifo.shape.gii")), "not a regular file"),
        // A FIFO no process writes to: read at once as empty, never waited on.
        ("exec", signal(&p("fifo.bin")), "missing the header line"),
        ("exec", mask(&format!("{}:CORTEX_LEFT:x", p("fifo.dlabel.nii"))), "unexpected end of data"),
        ("exec", signal(&p("short.shape.gii")), "external data file"),
        ("exec", signal(&p("offset.shape.gii")), "external data file"),
        ("exec", signal(&p("huge_dim.shape.gii")), "FSHAPE_MAX_VALUES"),
        ("exec", vec!["info".into(), p("huge_count.ply")], "4000000000"),
        ("exec", signal(&p("lh.thickness")), "2147483647"),
        ("exec", vec!["info".into(), p("bomb.ply.gz")], "decompresses to more than"),
        ("exec", signal(&p("bomb.csv.gz")), "past the mesh's 4 vertices (value 5 is here)"),
        ("exec", signal(&p("runaway.csv")), "past the mesh's 4 vertices (value 5 is here)"),
        // Pipes are read, with a look at their first bytes.
        ("cat /dev/zero |", vec!["info".into(), "/dev/stdin".into()], "unknown format"),
        ("cat /dev/zero |", signal("/dev/stdin"), "expected a signal file"),
        ("cat /dev/urandom |", signal("/dev/stdin"), "expected a signal file"),
        ("(echo thickness; yes 1) |", signal("/dev/stdin"), "past the mesh's 4 vertices (value 5 is here)"),
        ("exec", vec!["checkpoint".into(), "/dev/zero".into()], "device"),
        ("exec", signal(&format!("{}:CORTEX_LEFT", p("huge_surface.dscalar.nii"))), "expected 4, found 2000000000"),
        ("exec", signal(&format!("{}:CORTEX_LEFT", p("huge_matrix.dscalar.nii"))), "expected 1000000000, found 1"),
        ("exec", mask(&format!("{}:x", p("lh.huge.annot"))), "claims 2147483647"),
        ("exec", mask(&format!("{}:x", p("lh.zero.annot"))), "device"),
        ("exec", vec!["report".into(), p("fifo_run")], "not a regular file"),
        ("exec", vec!["report".into(), p("fifo_batch")], "not a regular file"),
        ("exec", vec!["report".into(), p("zero_run")], "not a regular file"),
        ("exec", vec!["report".into(), p("nested_run")], "recursion limit"),
    ];
    let mut failures = Vec::new();
    for (prefix, args, says) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run_limited(limit, prefix, &args);
        let clean = o.code == Some(1) && o.stderr.starts_with("error: ") && !o.stderr.contains("panicked");
        if !clean || !o.stderr.contains(says) {
            failures.push(format!("{prefix} fshape {args:?}: status {:?}, {:?}, stderr: {}", o.code, o.wall, o.stderr));
        }
    }
    assert!(
        failures.is_empty(),
        "with {} KiB of address space ({} KiB for a small file):\n{}",
        limit,
        base,
        failures.join("\n")
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
