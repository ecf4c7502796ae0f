//! Figures as journals print them, through the real binary on the virtual rig: every verb
//! that draws (`rig demo`, `rig calibrate`, `rig compare`, `rig experiment torque-sweep` and
//! `hold-release`, `rig design search`, `rig explain`'s report) at `--size single` (3.5 in) and `--size double` (7.2 in) writes SVGs
//! whose text is at least 7 pt at that width and clear of the plotted data
//! (`reporting::check::check_svg`), and PDFs of that printed width.

use std::path::{Path, PathBuf};
use std::time::Duration;

use assert_cmd::Command;
use reporting::figure::FigureSize;

fn rig() -> Command {
    let mut c = Command::cargo_bin("rig").expect("the rig binary is built");
    c.env_remove("RIG_PORT").timeout(Duration::from_secs(600));
    c
}

const SIZES: [(&str, FigureSize); 2] = [
    ("single", FigureSize::Single),
    ("double", FigureSize::Double),
];

/// Checks the SVG `path` printed at `size`: drawn at its width, nothing to report.
fn assert_prints_well(path: &Path, size: FigureSize) {
    let svg = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        svg.contains(&format!("<svg width=\"{}\"", size.width_px())),
        "{} is not drawn {} px wide",
        path.display(),
        size.width_px()
    );
    let problems = reporting::check::check_svg(&svg, size.width_in());
    assert!(
        problems.is_empty(),
        "{} at {size}:\n{}",
        path.display(),
        problems
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join("\n")
    );
}

/// The page width of the PDF `path`, pt.
fn pdf_width_pt(path: &Path) -> f64 {
    let bytes = std::fs::read(path).unwrap();
    reporting::check::pdf_page_pt(&bytes).expect("a PDF page").0
}

fn svgs_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(svgs_under(&p));
        } else if p.extension().is_some_and(|x| x == "svg") {
            out.push(p);
        }
    }
    out
}

#[test]
fn demo_figures_print_at_a_journal_width() {
    let dir = tempfile::tempdir().unwrap();
    for (name, size) in SIZES {
        let out = dir.path().join(name);
        rig()
            .args([
                "demo", "--quick", "--json", "--format", "pdf", "--size", name, "--out",
            ])
            .arg(&out)
            .assert()
            .success();
        let svgs = svgs_under(&out);
        assert_eq!(
            svgs.len(),
            4,
            "fig5, the sweep, two calibration fits: {svgs:?}"
        );
        for svg in &svgs {
            assert_prints_well(svg, size);
            // The PDF beside it is a page of the printed width.
            let w = pdf_width_pt(&svg.with_extension("pdf"));
            assert!(
                (w - size.width_in() * 72.0).abs() < 0.01,
                "{}: {w} pt",
                svg.display()
            );
        }
    }
}

#[test]
fn the_other_verbs_figures_print_at_a_journal_width() {
    let dir = tempfile::tempdir().unwrap();
    // A quick measured sweep, the input of `rig compare`.
    let measured = dir.path().join("measured.csv");
    rig()
        .args([
            "sim",
            "torque-sweep",
            "--levels",
            "4",
            "--repeats",
            "1",
            "--rest",
            "1",
            "--csv",
        ])
        .arg(&measured)
        .assert()
        .success();
    for (name, size) in SIZES {
        let at = dir.path().join(name);
        std::fs::create_dir(&at).unwrap();
        // rig calibrate on the virtual rig.
        let cal = at.join("calibrate");
        rig()
            .args([
                "--sim",
                "--speed",
                "20",
                "calibrate",
                "--yes",
                "--json",
                "--size",
                name,
                "--out",
            ])
            .arg(&cal)
            .assert()
            .success();
        for plot in ["torque_current.svg", "no_load.svg"] {
            assert_prints_well(&cal.join(plot), size);
        }
        // rig compare's gap plot.
        let gap = at.join("gap.svg");
        rig()
            .args(["compare", "--json", "--measured"])
            .arg(&measured)
            .arg("--svg")
            .arg(&gap)
            .args(["--size", name])
            .assert()
            .success();
        assert_prints_well(&gap, size);
        // rig experiment torque-sweep --svg and hold-release.
        let sweep = at.join("sweep.svg");
        rig()
            .args([
                "--sim",
                "--speed",
                "20",
                "experiment",
                "torque-sweep",
                "--quick",
                "--json",
                "--csv",
            ])
            .arg(at.join("sweep.csv"))
            .arg("--svg")
            .arg(&sweep)
            .args(["--size", name])
            .assert()
            .success();
        assert_prints_well(&sweep, size);
        let hold = at.join("hold.csv");
        rig()
            .args([
                "--sim",
                "--speed",
                "20",
                "experiment",
                "hold-release",
                "--hold",
                "2",
                "--csv",
            ])
            .arg(&hold)
            .args(["--size", name, "--format", "pdf"])
            .assert()
            .success();
        assert_prints_well(&hold.with_extension("svg"), size);
        let w = pdf_width_pt(&hold.with_extension("pdf"));
        assert!(
            (w - size.width_in() * 72.0).abs() < 0.01,
            "hold-release: {w} pt"
        );
        // rig explain's report: the residuals before and after.
        let report = at.join("explain");
        rig()
            .args(["explain", "--json", "--replicates", "50", "--measured"])
            .arg(&measured)
            .arg("--report")
            .arg(&report)
            .args(["--size", name])
            .assert()
            .success();
        for plot in ["residuals_before.svg", "residuals_after.svg"] {
            assert_prints_well(&report.join(plot), size);
        }
        // rig design search --svg: the front.
        let front = at.join("front.svg");
        rig()
            .args([
                "design",
                "search",
                "--teeth",
                "47,53",
                "--max-n",
                "1",
                "--max-sum-difference",
                "1",
                "--stop-margin",
                "0.1",
                "--limit",
                "5",
                "--svg",
            ])
            .arg(&front)
            .args(["--size", name])
            .assert()
            .success();
        assert_prints_well(&front, size);
    }
}

#[test]
fn pixel_sizes_keep_working_and_a_size_needs_a_figure() {
    let dir = tempfile::tempdir().unwrap();
    let hold = dir.path().join("hold.csv");
    rig()
        .args([
            "--sim",
            "--speed",
            "20",
            "experiment",
            "hold-release",
            "--hold",
            "2",
            "--csv",
        ])
        .arg(&hold)
        .args(["--size", "800", "--format", "png"])
        .assert()
        .success();
    // 800 px printed at 96 px/in: 8.33 in, its text still 7 pt or more there.
    assert_prints_well(&hold.with_extension("svg"), FigureSize::Pixels(800));
    let png = std::fs::read(hold.with_extension("png")).unwrap();
    assert_eq!(u32::from_be_bytes(png[16..20].try_into().unwrap()), 800);
    // --size without the --svg it would draw is refused, naming what to add.
    let e = rig()
        .args(["compare", "--measured", "x.csv", "--size", "single"])
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    let e = String::from_utf8_lossy(&e);
    assert!(e.contains("--size") && e.contains("--svg FILE.svg"), "{e}");
    let e = rig()
        .args(["demo", "--size", "huge"])
        .assert()
        .failure()
        .get_output()
        .stderr
        .clone();
    assert!(String::from_utf8_lossy(&e).contains("`single` (3.5 in)"));
}
