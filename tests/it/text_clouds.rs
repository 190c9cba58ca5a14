//! Text clouds (XYZ, PTS, CSV): the same curves as the same points in PLY; a column spec and
//! skipped header lines; lines that do not parse named.

use glam::DVec3;
use std::fmt::Write;
use std::process::Command;

fn crease(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_crease")).args(args).output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn text_clouds_give_the_curves_of_the_same_points_in_ply() {
    let d = tempfile::tempdir().unwrap();
    let cube = crease::synth::sample(&crease::synth::shape("cube", 90.0).unwrap(), &crease::synth::SynthOptions { n: 20_000, ..Default::default() });
    let ply = d.path().join("cube.ply");
    let mut w = crease::io::PointWriter::create(&ply, &crease::io::WriteOptions { scale: 1e-6, offset: DVec3::ZERO, epsg: None }).unwrap();
    w.write(&cube, &vec![0; cube.len()]).unwrap();
    w.finish().unwrap();
    // (Rust prints the shortest text that reads back as the same double.)
    let (mut xyz, mut pts, mut csv, mut spec) =
        (String::new(), format!("{}\n", cube.len()), "id;\"X\";\"Y\";\"Z\";class\n".to_string(), "# scanner export\n# v2\n".to_string());
    for (i, p) in cube.iter().enumerate() {
        writeln!(xyz, "{} {} {}", p.x, p.y, p.z).unwrap();
        writeln!(pts, "{}\t{}\t{}\t-1200 255 255 255", p.x, p.y, p.z).unwrap();
        writeln!(csv, "{i};{};{};{};2", p.x, p.y, p.z).unwrap();
        writeln!(spec, "{},{},{},{}", p.z, p.y, 6, p.x).unwrap();
    }
    // (As a Windows program writes it: a byte order mark, and CRLF line ends.)
    let windows = format!("\u{feff}{}", xyz.replace('\n', "\r\n"));
    let files = [
        ("windows.xyz", windows, vec![]),
        ("cube.xyz", xyz, vec![]),
        ("cube.pts", pts, vec![]),
        ("cube.csv", csv, vec!["--classes", "2"]),
        ("spec.txt", spec, vec!["--columns", "3,1,0", "--skip-lines", "2"]),
    ];
    let run = |input: &std::path::Path, extra: &[&str]| {
        let out = d.path().join(format!("run_{}", input.file_name().unwrap().to_string_lossy()));
        let (code, err) = crease(&[&["extract", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"][..], extra].concat());
        assert_eq!(code, 0, "{}: {err}", input.display());
        std::fs::read(out.join("curves.obj")).unwrap()
    };
    let want = run(&ply, &[]);
    assert_eq!(crease::curves::read_obj(&d.path().join("run_cube.ply/curves.obj")).unwrap().len(), 12);
    for (name, text, extra) in &files {
        let p = d.path().join(name);
        std::fs::write(&p, text).unwrap();
        assert!(run(&p, extra) == want, "{name}: other curves than the PLY's");
    }
    // A header naming the columns puts the class where it says: --classes 3 keeps nothing.
    let (code, err) = crease(&["extract", d.path().join("cube.csv").to_str().unwrap(), "-o", d.path().join("none").to_str().unwrap(), "-q", "--classes", "3"]);
    assert_eq!(code, crease::error::exit::DATA, "{err}");

    let long = format!("0 0 0\n1 1 1\n{}\n", "7 ".repeat(64 * 1024));
    for (name, text, says) in [
        ("short.xyz", "0 0 0\n1 1\n", "line 2 has 2 values"),
        ("word.csv", "x,y,z\n1,2,three\n", "line 2: 'three' in column 2 is not a number"),
        ("long.xyz", long.as_str(), "line 3 is longer than"),
    ] {
        let p = d.path().join(name);
        std::fs::write(&p, text).unwrap();
        let (code, err) = crease(&["info", p.to_str().unwrap()]);
        assert_eq!(code, crease::error::exit::DATA, "{err}");
        assert!(err.trim_end().lines().count() == 1 && err.contains(name) && err.contains(says), "{err}");
    }
}

/// A spreadsheet's export with decimal commas and semicolons between the values ("0,5;1,25;2")
/// was read as six values a line, x, y and z the first three: integers and digit strings, a
/// strip ten million units long that took minutes to tile. It is refused, naming the line.
#[test]
fn decimal_commas_are_refused_naming_the_line() {
    let d = tempfile::tempdir().unwrap();
    let p = d.path().join("comma.csv");
    let lines: String = (0..2000).map(|k| format!("{},{:07};0,5;{},25\n", k % 2, (k * 4999) % 9_999_991, k % 3)).collect();
    std::fs::write(&p, format!("x;y;z\n{lines}")).unwrap();
    let run = d.path().join("run");
    for args in [vec!["info", p.to_str().unwrap()], vec!["extract", p.to_str().unwrap(), "-o", run.to_str().unwrap(), "-q"]] {
        let (code, err) = crease(&args);
        assert_eq!(code, crease::error::exit::DATA, "{args:?}: {err}");
        assert!(err.trim_end().lines().count() == 1 && err.contains("comma.csv") && err.contains("line 2") && err.contains("decimal"), "{err}");
    }
    assert!(!run.join("curves.obj").exists());
}

/// A PTS file whose count line declares far more points than it holds (5e9 over 20,000 lines)
/// was read without a word. Its points are read, and a warning names the file and both counts;
/// a count that matches says nothing.
#[test]
fn a_pts_count_that_is_not_the_points_held_is_warned_about() {
    let d = tempfile::tempdir().unwrap();
    let cube = crease::synth::sample(&crease::synth::shape("cube", 90.0).unwrap(), &crease::synth::SynthOptions { n: 20_000, ..Default::default() });
    let body: String = cube.iter().map(|p| format!("{} {} {} 0 255 255 255\n", p.x, p.y, p.z)).collect();
    for (name, count, warned) in [("wrong.pts", 5_000_000_000u64, true), ("right.pts", cube.len() as u64, false)] {
        let p = d.path().join(name);
        std::fs::write(&p, format!("{count}\n{body}")).unwrap();
        let out = d.path().join(format!("run_{name}"));
        let (code, err) = crease(&["extract", p.to_str().unwrap(), "-o", out.to_str().unwrap(), "-q"]);
        assert_eq!(code, 0, "{err}");
        assert_eq!(crease::curves::read_obj(&out.join("curves.obj")).unwrap().len(), 12, "{name}");
        let says = format!("{}: its PTS count lines declare {count} points; it holds {}", p.display(), cube.len());
        assert_eq!(err.contains(&says), warned, "{name}: {err}");
        assert_eq!(err.contains("PTS count"), warned, "{name}: {err}");
    }
}
