//! Measures a figure as a journal prints it: [`check_svg`] reads an SVG the figures of
//! [`crate::plot`] write (its texts' font sizes and positions, the framed plot areas and the
//! lines and points drawn in them) and reports every text smaller than
//! [`MIN_TEXT_PT`] at the printed width, every text whose box lies on the plotted data and
//! every text that writes a symbol or unit in an ASCII stand-in ([`ascii_stand_in`]: `tau_`
//! for τ, `w_n` for ω_n, `+-` for ±, a unit in brackets where the figures write
//! `quantity, unit`, [`crate::plot::axis_label`]).
//!
//! Text boxes are estimated, not shaped: [`text_width_px`] is wider than a sans-serif face
//! sets (0.6 em a character), so a text it passes fits.

use crate::figure::MIN_TEXT_PT;

/// Estimated width of `text` in a sans-serif font `px` high, px (0.6 em a character: wider
/// than DejaVu Sans or Helvetica set an average text).
pub fn text_width_px(text: &str, px: f64) -> f64 {
    text.chars().count() as f64 * 0.6 * px
}

/// What is wrong with a figure.
#[derive(Debug, Clone, PartialEq)]
pub enum Problem {
    /// A text prints smaller than [`MIN_TEXT_PT`].
    SmallText {
        /// The text.
        text: String,
        /// Its printed size, pt.
        pt: f64,
    },
    /// A text's box lies on a plotted line or point.
    OnData {
        /// The text.
        text: String,
        /// Its box, px of the drawing: (left, top, right, bottom).
        text_box: (f64, f64, f64, f64),
    },
    /// A text writes a symbol or unit as ASCII where a journal prints it
    /// ([`ascii_stand_in`]).
    AsciiSymbol {
        /// The text.
        text: String,
        /// The stand-in found, and what the figures write instead.
        stand_in: String,
    },
    /// The SVG has no `width` or no framed plot area (not a figure of [`crate::plot`]).
    NotAFigure(String),
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::SmallText { text, pt } => write!(
                f,
                "'{text}' prints at {pt:.1} pt, under the {MIN_TEXT_PT} pt a journal prints"
            ),
            Self::OnData { text, text_box } => write!(
                f,
                "'{text}' (box {:.0},{:.0} to {:.0},{:.0} px) lies on the plotted data",
                text_box.0, text_box.1, text_box.2, text_box.3
            ),
            Self::AsciiSymbol { text, stand_in } => write!(
                f,
                "'{text}' writes {stand_in} (symbols as printed, units as `quantity, unit`)"
            ),
            Self::NotAFigure(why) => write!(f, "not a figure: {why}"),
        }
    }
}

/// Greek letters spelled out in ASCII, as the figures must not write them, and the letter.
const GREEK: [(&str, &str); 12] = [
    ("tau", "τ"),
    ("omega", "ω"),
    ("mu", "μ"),
    ("Lambda", "Λ"),
    ("lambda", "λ"),
    ("rho", "ρ"),
    ("sigma", "σ"),
    ("theta", "θ"),
    ("alpha", "α"),
    ("kappa", "κ"),
    ("eta", "η"),
    ("phi", "φ"),
];

/// The first ASCII stand-in in the figure text `text`, described with what replaces it
/// (none: `text` writes its symbols and units as printed): a Greek letter spelled out as a
/// word (`tau_rot`, `mu_d Lambda`), `w_n` or `w_` for ω, `+-` for ±, and a unit in
/// brackets (`[A]`, `[rad/s]`; the figures write `quantity, unit`).
pub fn ascii_stand_in(text: &str) -> Option<String> {
    // Words: runs of ASCII letters (so `tau_rot` has the word `tau`, `C1` the word `C`).
    let mut words = Vec::new();
    let mut start = None;
    for (k, c) in text
        .char_indices()
        .chain(std::iter::once((text.len(), ' ')))
    {
        match (c.is_ascii_alphabetic(), start) {
            (true, None) => start = Some(k),
            (false, Some(s)) => {
                words.push((s, &text[s..k]));
                start = None;
            }
            _ => {}
        }
    }
    for &(at, w) in &words {
        if let Some((_, greek)) = GREEK.iter().find(|(name, _)| *name == w) {
            return Some(format!("`{w}` for {greek}"));
        }
        if w == "w" && text[at + 1..].starts_with('_') {
            return Some("`w_` for ω".into());
        }
    }
    if text.contains("+-") || text.contains("-+") {
        return Some("`+-` for ±".into());
    }
    let mut rest = text;
    while let Some(open) = rest.find('[') {
        let after = &rest[open + 1..];
        let Some(close) = after.find(']') else { break };
        let inside = &after[..close];
        let unit_like = !inside.is_empty()
            && inside.chars().count() <= 8
            && inside.chars().any(char::is_alphabetic)
            && inside
                .chars()
                .all(|c| c.is_alphabetic() || " /%°·^".contains(c));
        if unit_like {
            return Some(format!("`[{inside}]` for `, {inside}`"));
        }
        rest = &after[close + 1..];
    }
    None
}

/// One element of the SVG: its name, attributes and (for text) its content.
struct Element {
    name: String,
    attrs: Vec<(String, String)>,
    text: String,
    /// The smallest `font-size` of its `tspan`s relative to its own (1 without).
    smallest: f64,
}

impl Element {
    fn attr(&self, name: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }

    fn num(&self, name: &str) -> Option<f64> {
        self.attr(name)?.trim().trim_end_matches("px").parse().ok()
    }
}

/// The elements of `svg`, in order (a small reader of the SVG plotters writes: no
/// comments, CDATA or nested text).
fn elements(svg: &str) -> Vec<Element> {
    let mut out = Vec::new();
    let mut rest = svg;
    while let Some(at) = rest.find('<') {
        rest = &rest[at + 1..];
        let Some(end) = rest.find('>') else { break };
        let tag = &rest[..end];
        rest = &rest[end + 1..];
        if tag.starts_with('/') || tag.starts_with('?') || tag.starts_with('!') {
            continue;
        }
        let tag = tag.trim_end_matches('/');
        let name_end = tag.find(char::is_whitespace).unwrap_or(tag.len());
        let name = tag[..name_end].to_string();
        let mut attrs = Vec::new();
        let mut a = &tag[name_end..];
        while let Some(eq) = a.find("=\"") {
            let key = a[..eq].trim().to_string();
            let value_from = eq + 2;
            let Some(close) = a[value_from..].find('"') else {
                break;
            };
            attrs.push((key, a[value_from..value_from + close].to_string()));
            a = &a[value_from + close + 1..];
        }
        let mut text = String::new();
        let mut smallest = 1.0f64;
        if name == "text"
            && let Some(close) = rest.find("</text>")
        {
            text = plain_text(rest[..close].trim());
            for span in rest[..close].split("<tspan").skip(1) {
                if let Some(pct) = span
                    .split("font-size=\"")
                    .nth(1)
                    .and_then(|v| v.split('"').next())
                    .and_then(|v| v.strip_suffix('%'))
                    .and_then(|v| v.parse::<f64>().ok())
                {
                    smallest = smallest.min(pct / 100.0);
                }
            }
            rest = &rest[close..];
        }
        out.push(Element {
            name,
            attrs,
            text,
            smallest,
        });
    }
    out
}

/// The text of a `text` element's content `s` as the code wrote it: subscripts
/// ([`crate::plot::subscripts`]) back after `_`, escapes undone.
fn plain_text(s: &str) -> String {
    let mut plain = String::new();
    let mut tag: Option<String> = None;
    for c in s.chars() {
        match (&mut tag, c) {
            (None, '<') => tag = Some(String::new()),
            (Some(t), '>') => {
                if t.starts_with("tspan") && t.contains("baseline-shift=\"sub\"") {
                    plain.push('_');
                }
                tag = None;
            }
            (Some(t), c) => t.push(c),
            (None, c) => plain.push(c),
        }
    }
    unescape(&plain)
}

/// Every text of the SVG figure `svg`, in order, as the code wrote it (a subscript after
/// `_`): what a test asserts a figure says.
pub fn figure_texts(svg: &str) -> Vec<String> {
    elements(svg)
        .into_iter()
        .filter(|e| e.name == "text" && !e.text.is_empty())
        .map(|e| e.text)
        .collect()
}

fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}

/// An axis-aligned box: (left, top, right, bottom), px.
type Box2 = (f64, f64, f64, f64);

/// The box of a text element as plotters places it (`text-anchor`, `dy` of its vertical
/// anchor, a rotation about its anchor point).
fn text_box(e: &Element, px: f64) -> Option<Box2> {
    let (x, y) = (e.num("x")?, e.num("y")?);
    let w = text_width_px(&e.text, px);
    let (l, r) = match e.attr("text-anchor") {
        Some("middle") => (x - w / 2.0, x + w / 2.0),
        Some("end") => (x - w, x),
        _ => (x, x + w),
    };
    let (t, b) = match e.attr("dy") {
        Some("0.76em") => (y, y + px),
        Some("0.5ex") => (y - px / 2.0, y + px / 2.0),
        Some("-0.5ex") => (y - px, y),
        _ => (y - 0.8 * px, y + 0.2 * px),
    };
    let turns = e
        .attr("transform")
        .and_then(|t| t.strip_prefix("rotate("))
        .and_then(|t| t.split(',').next())
        .and_then(|a| a.trim().parse::<f64>().ok())
        .unwrap_or(0.0);
    if turns == 0.0 {
        return Some((l, t, r, b));
    }
    let (s, c) = turns.to_radians().sin_cos();
    let corners = [(l, t), (r, t), (l, b), (r, b)].map(|(px_, py_)| {
        let (dx, dy) = (px_ - x, py_ - y);
        (x + dx * c - dy * s, y + dx * s + dy * c)
    });
    let fold = |f: fn(f64, f64) -> f64, init: f64, k: usize| {
        corners
            .iter()
            .map(|p| if k == 0 { p.0 } else { p.1 })
            .fold(init, f)
    };
    Some((
        fold(f64::min, f64::INFINITY, 0),
        fold(f64::min, f64::INFINITY, 1),
        fold(f64::max, f64::NEG_INFINITY, 0),
        fold(f64::max, f64::NEG_INFINITY, 1),
    ))
}

/// Whether the segment `a`-`b` passes through box `r` (Liang-Barsky clipping).
fn segment_hits(a: (f64, f64), b: (f64, f64), r: Box2) -> bool {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - r.0),
        (dx, r.2 - a.0),
        (-dy, a.1 - r.1),
        (dy, r.3 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return false;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

fn inside(p: (f64, f64), r: Box2) -> bool {
    const SLACK: f64 = 1.0;
    p.0 >= r.0 - SLACK && p.0 <= r.2 + SLACK && p.1 >= r.1 - SLACK && p.1 <= r.3 + SLACK
}

fn points(e: &Element) -> Vec<(f64, f64)> {
    e.attr("points")
        .unwrap_or_default()
        .split_whitespace()
        .filter_map(|p| {
            let (x, y) = p.split_once(',')?;
            Some((x.parse().ok()?, y.parse().ok()?))
        })
        .collect()
}

/// The first page's size of the PDF `pdf` as printed, (width, height) in pt, read from its
/// first `/MediaBox`; None when it has none that parses.
pub fn pdf_page_pt(pdf: &[u8]) -> Option<(f64, f64)> {
    let text = String::from_utf8_lossy(pdf);
    let at = text.find("/MediaBox")? + "/MediaBox".len();
    let nums: Vec<f64> = text[at..]
        .trim_start()
        .trim_start_matches('[')
        .split_whitespace()
        .take(4)
        .map(|n| n.trim_end_matches(']').parse().ok())
        .collect::<Option<_>>()?;
    let [x0, y0, x1, y1] = nums[..] else {
        return None;
    };
    Some((x1 - x0, y1 - y0))
}

/// The problems of the SVG figure `svg` printed `printed_width_in` inches wide: every text
/// under [`MIN_TEXT_PT`] there, every text whose box lies on a line or point plotted in a
/// framed plot area (the unfilled rectangles [`crate::plot`] draws around its plots), and
/// every text with an ASCII stand-in for a symbol or unit ([`ascii_stand_in`]). An SVG
/// without a width or plot area is [`Problem::NotAFigure`].
pub fn check_svg(svg: &str, printed_width_in: f64) -> Vec<Problem> {
    let all = elements(svg);
    let Some(width_px) = all
        .iter()
        .find(|e| e.name == "svg")
        .and_then(|e| e.num("width"))
        .filter(|w| *w > 0.0)
    else {
        return vec![Problem::NotAFigure("the SVG states no width".into())];
    };
    let pt_per_px = printed_width_in * 72.0 / width_px;
    let frames: Vec<Box2> = all
        .iter()
        .filter(|e| e.name == "rect" && e.attr("fill") == Some("none"))
        .filter_map(|e| {
            let (x, y) = (e.num("x")?, e.num("y")?);
            Some((x, y, x + e.num("width")?, y + e.num("height")?))
        })
        .collect();
    let mut problems = Vec::new();
    if frames.is_empty() {
        problems.push(Problem::NotAFigure("no framed plot area".into()));
    }
    let in_a_frame = |p: (f64, f64)| frames.iter().any(|&f| inside(p, f));
    // The data: polylines and circles inside a plot area (a legend's samples lie below it).
    let mut segments = Vec::new();
    let mut dots = Vec::new();
    for e in &all {
        match e.name.as_str() {
            "polyline" => {
                let p = points(e);
                if !p.is_empty() && p.iter().all(|&q| in_a_frame(q)) {
                    segments.extend(p.windows(2).map(|w| (w[0], w[1])));
                    if p.len() == 1 {
                        segments.push((p[0], p[0]));
                    }
                }
            }
            "circle" => {
                if let (Some(cx), Some(cy), Some(r)) = (e.num("cx"), e.num("cy"), e.num("r"))
                    && in_a_frame((cx, cy))
                {
                    dots.push((cx, cy, r));
                }
            }
            _ => {}
        }
    }
    for e in all
        .iter()
        .filter(|e| e.name == "text" && !e.text.is_empty())
    {
        let Some(px) = e.num("font-size") else {
            continue;
        };
        // Its smallest part: a subscript is smaller than its text.
        let pt = px * e.smallest * pt_per_px;
        if pt < MIN_TEXT_PT - 1e-9 {
            problems.push(Problem::SmallText {
                text: e.text.clone(),
                pt,
            });
        }
        if let Some(stand_in) = ascii_stand_in(&e.text) {
            problems.push(Problem::AsciiSymbol {
                text: e.text.clone(),
                stand_in,
            });
        }
        let Some(b) = text_box(e, px) else { continue };
        let on_line = segments.iter().any(|&(a, c)| segment_hits(a, c, b));
        let on_dot = dots
            .iter()
            .any(|&(x, y, r)| inside((x, y), (b.0 - r, b.1 - r, b.2 + r, b.3 + r)));
        if on_line || on_dot {
            problems.push(Problem::OnData {
                text: e.text.clone(),
                text_box: b,
            });
        }
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 336 px figure (a 3.5 in column) with a framed plot area, a line across it and
    /// `texts` (x, y, font px, anchor, text).
    fn figure(texts: &[(f64, f64, f64, &str, &str)]) -> String {
        let mut svg = String::from(
            "<svg width=\"336\" height=\"200\" viewBox=\"0 0 336 200\" xmlns=\"http://www.w3.org/2000/svg\">\n<rect x=\"0\" y=\"0\" width=\"336\" height=\"200\" opacity=\"1\" fill=\"#FFFFFF\" stroke=\"none\"/>\n<rect x=\"60\" y=\"20\" width=\"260\" height=\"140\" opacity=\"1\" fill=\"none\" stroke=\"#000000\"/>\n<polyline fill=\"none\" opacity=\"1\" stroke=\"#0072B2\" stroke-width=\"2\" points=\"60,150 190,90 320,30 \"/>\n<circle cx=\"100\" cy=\"140\" r=\"3\" opacity=\"1\" fill=\"#D55E00\" stroke=\"none\" stroke-width=\"1\"/>\n",
        );
        for (x, y, px, anchor, text) in texts {
            svg += &format!(
                "<text x=\"{x}\" y=\"{y}\" dy=\"0.76em\" text-anchor=\"{anchor}\" font-family=\"sans-serif\" font-size=\"{px}\" opacity=\"1\" fill=\"#000000\">\n{text}\n</text>\n"
            );
        }
        svg + "</svg>\n"
    }

    #[test]
    fn a_clear_figure_at_7_pt_passes() {
        // 7 pt at 3.5 in over 336 px: 7 / 72 * 96 = 9.33 px.
        let svg = figure(&[
            (190.0, 170.0, 9.34, "middle", "τ_rot, N m"),
            (62.0, 2.0, 9.34, "start", "(a) current"),
        ]);
        assert_eq!(check_svg(&svg, 3.5), vec![]);
    }

    #[test]
    fn a_5_pt_text_is_reported() {
        // 5 pt at 3.5 in over 336 px: 6.67 px.
        let svg = figure(&[(190.0, 170.0, 6.67, "middle", "tick")]);
        match check_svg(&svg, 3.5).as_slice() {
            [Problem::SmallText { text, pt }] => {
                assert_eq!(text, "tick");
                assert!((pt - 5.0).abs() < 0.01, "{pt}");
            }
            other => panic!("{other:?}"),
        }
        // The same text on a figure printed twice as wide is 10 pt: fine.
        assert_eq!(check_svg(&svg, 7.0), vec![]);
    }

    #[test]
    fn a_label_on_the_data_is_reported() {
        // On the line (x 180..220 around y 95), and on the point at (100, 140).
        let svg = figure(&[
            (170.0, 88.0, 10.0, "start", "release"),
            (96.0, 136.0, 10.0, "start", "x"),
            (250.0, 120.0, 10.0, "start", "free"),
        ]);
        let on: Vec<String> = check_svg(&svg, 3.5)
            .iter()
            .map(|p| match p {
                Problem::OnData { text, .. } => text.clone(),
                other => panic!("{other}"),
            })
            .collect();
        assert_eq!(on, ["release", "x"]);
    }

    #[test]
    fn ascii_stand_ins_for_symbols_and_units_are_reported() {
        for (text, found) in [
            ("tau_rot [N m]", "`tau` for τ"),
            ("w_n [rad/s]", "`w_` for ω"),
            ("cam speed w_n, rad/s", "`w_` for ω"),
            ("mu_d Lambda", "`mu` for μ"),
            ("|rho|", "`rho` for ρ"),
            ("mean, bars +-1 sd", "`+-` for ±"),
            ("i_in [A]", "`[A]` for `, A`"),
            ("t [s]", "`[s]` for `, s`"),
            ("measured - model [mA]", "`[mA]` for `, mA`"),
        ] {
            assert_eq!(ascii_stand_in(text).as_deref(), Some(found), "{text}");
        }
        // As printed: Unicode symbols, `quantity, unit`, and words that merely contain a
        // letter's name or brackets that hold no unit.
        for text in [
            "τ_rot, N m",
            "ω_n, rad/s",
            "μ_d Λ",
            "|ρ|",
            "current (Fig. 8): mean, bars ±1 SD over repeats",
            "Torque-current: |τ_cam| = C1 i_in + C2 (Eq. 15)",
            "stop after vibration vs tooth strength",
            "test point (run order)",
            "range [0, 1]",
            "paper: held 14.5 s",
            "fit: 0.1234 x +5, R² 0.99",
            "motor temperature, °C",
            "measured − model, mA",
        ] {
            assert_eq!(ascii_stand_in(text), None, "{text}");
        }
        // In a figure: reported with the stand-in, beside nothing else.
        let svg = figure(&[(190.0, 170.0, 9.34, "middle", "tau_rot [N m]")]);
        assert_eq!(
            check_svg(&svg, 3.5),
            vec![Problem::AsciiSymbol {
                text: "tau_rot [N m]".into(),
                stand_in: "`tau` for τ".into(),
            }]
        );
        let fixed = figure(&[(190.0, 170.0, 9.34, "middle", "τ_rot, N m")]);
        assert_eq!(check_svg(&fixed, 3.5), vec![]);
    }

    #[test]
    fn subscripts_are_read_back_and_checked() {
        let svg = crate::plot::subscripts(&figure(&[
            (190.0, 170.0, 10.67, "middle", "τ_rot, N m"),
            (62.0, 2.0, 10.67, "start", "w_n [rad/s]"),
        ]));
        assert!(svg.contains("τ<tspan baseline-shift=\"sub\" font-size=\"88%\">rot</tspan>, N m"));
        assert_eq!(figure_texts(&svg), ["τ_rot, N m", "w_n [rad/s]"]);
        // Measured at the subscript's size: 8 pt text keeps 7 pt subscripts, 7 pt does not.
        let at = |pt: f64| {
            let px = pt / 72.0 * 96.0;
            crate::plot::subscripts(&figure(&[(190.0, 170.0, px, "middle", "τ_rot, N m")]))
        };
        assert_eq!(check_svg(&at(8.0), 3.5), vec![]);
        assert!(matches!(
            check_svg(&at(7.0), 3.5).as_slice(),
            [Problem::SmallText { pt, .. }] if (pt - 7.0 * 0.88).abs() < 0.01
        ));
        assert_eq!(
            check_svg(&svg, 3.5),
            vec![Problem::AsciiSymbol {
                text: "w_n [rad/s]".into(),
                stand_in: "`w_` for ω".into(),
            }]
        );
    }

    #[test]
    fn an_svg_without_a_plot_area_is_not_a_figure() {
        let svg = "<svg width=\"100\" height=\"100\"></svg>";
        assert!(matches!(
            check_svg(svg, 3.5).as_slice(),
            [Problem::NotAFigure(_)]
        ));
    }

    #[test]
    fn rotated_text_turns_its_box() {
        let e = Element {
            name: "text".into(),
            attrs: vec![
                ("x".into(), "10".into()),
                ("y".into(), "100".into()),
                ("dy".into(), "0.76em".into()),
                ("text-anchor".into(), "middle".into()),
                ("transform".into(), "rotate(270, 10, 100)".into()),
            ],
            text: "abcdefghij".into(),
            smallest: 1.0,
        };
        let b = text_box(&e, 10.0).unwrap();
        // 60 px of text turned upright: 60 px high, 10 px wide, to the anchor's right.
        assert!(
            (b.3 - b.1 - 60.0).abs() < 1e-9 && (b.2 - b.0 - 10.0).abs() < 1e-9,
            "{b:?}"
        );
    }
}
