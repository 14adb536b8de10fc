//! Pictures of a planar walker's gait: one row per policy, the stick figure drawn at regular
//! times over the ground, at its true position, so that stride and speed read off the picture.

use std::fmt::Write as _;

/// One frame: the figure's polylines, points `(x, z)` in metres.
pub type Frame = Vec<Vec<[f64; 2]>>;

/// One row of a [`filmstrip_svg`]: a label and the frames, oldest first.
#[derive(Debug, Clone, PartialEq)]
pub struct GaitRow {
    /// Shown above the row (e.g. the policy and its walked distance).
    pub label: String,
    /// The figures, drawn over each other in order; later frames darker.
    pub frames: Vec<Frame>,
}

/// An SVG of `rows` on one metric scale (the same metres per pixel in every row and both axes),
/// each row with its ground line at z = 0. Non-finite points are skipped.
pub fn filmstrip_svg(title: &str, rows: &[GaitRow]) -> String {
    const W: f64 = 1000.0;
    const MARGIN: f64 = 20.0;
    const TITLE: f64 = 30.0;
    const LABEL: f64 = 18.0;
    const MAX_SCALE: f64 = 400.0;
    let points = || {
        rows.iter()
            .flat_map(|r| r.frames.iter().flatten().flatten())
            .filter(|p| p[0].is_finite() && p[1].is_finite())
    };
    let (mut x0, mut x1, mut z1) = (f64::INFINITY, f64::NEG_INFINITY, 0.1f64);
    for p in points() {
        x0 = x0.min(p[0]);
        x1 = x1.max(p[0]);
        z1 = z1.max(p[1]);
    }
    if !(x0.is_finite() && x1.is_finite()) {
        (x0, x1) = (0.0, 1.0);
    }
    // Pixels per metre: the whole walk across the width, at most `MAX_SCALE`.
    let scale = ((W - 2.0 * MARGIN) / (x1 - x0).max(1e-9)).min(MAX_SCALE);
    let row_h = z1 * scale + LABEL + 12.0;
    let h = TITLE + rows.len() as f64 * row_h + MARGIN;
    let mut s = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{W}\" height=\"{h:.0}\" \
         viewBox=\"0 0 {W} {h:.0}\" font-family=\"sans-serif\" font-size=\"13\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"{MARGIN}\" y=\"20\" font-size=\"15\">{}</text>\n",
        escape(title)
    );
    for (k, row) in rows.iter().enumerate() {
        let top = TITLE + k as f64 * row_h;
        let ground = top + LABEL + z1 * scale;
        let _ = writeln!(
            s,
            "<text x=\"{MARGIN}\" y=\"{:.1}\">{}</text>\n\
             <line x1=\"{MARGIN}\" y1=\"{ground:.1}\" x2=\"{:.1}\" y2=\"{ground:.1}\" \
             stroke=\"#888\" stroke-width=\"1\"/>",
            top + 13.0,
            escape(&row.label),
            W - MARGIN
        );
        let n = row.frames.len().max(1) as f64;
        for (i, frame) in row.frames.iter().enumerate() {
            let opacity = 0.25 + 0.75 * (i as f64 + 1.0) / n;
            for line in frame {
                let pts: Vec<String> = line
                    .iter()
                    .filter(|p| p[0].is_finite() && p[1].is_finite())
                    .map(|p| {
                        format!(
                            "{:.1},{:.1}",
                            MARGIN + (p[0] - x0) * scale,
                            ground - p[1] * scale
                        )
                    })
                    .collect();
                if pts.len() >= 2 {
                    let _ = writeln!(
                        s,
                        "<polyline points=\"{}\" fill=\"none\" stroke=\"#1f77b4\" \
                         stroke-opacity=\"{opacity:.2}\" stroke-width=\"1.5\"/>",
                        pts.join(" ")
                    );
                }
            }
        }
    }
    s.push_str("</svg>\n");
    s
}

fn escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_share_one_scale_and_the_ground_is_at_zero() {
        // Two one-segment "figures": a 1 m pole at x = 0 and one at x = 2 m.
        let pole = |x: f64| vec![vec![[x, 0.0], [x, 1.0]]];
        let rows = [
            GaitRow {
                label: "a <b>".into(),
                frames: vec![pole(0.0), pole(2.0)],
            },
            GaitRow {
                label: "c".into(),
                frames: vec![pole(1.0), vec![vec![[f64::NAN, 0.0], [1.0, 0.5]]]],
            },
        ];
        let svg = filmstrip_svg("t", &rows);
        assert!(svg.contains("a &lt;b&gt;"));
        // 960 px for 2 m would be 480 px per metre, capped at 400; row height 400 + 30; ground
        // of row 0 at 30 + 18 + 400.
        assert!(svg.contains("points=\"20.0,448.0 20.0,48.0\""), "{svg}");
        assert!(svg.contains("points=\"820.0,448.0 820.0,48.0\""), "{svg}");
        assert!(svg.contains("points=\"420.0,878.0 420.0,478.0\""), "{svg}");
        // The polyline with a NaN point keeps too few points to draw.
        assert_eq!(svg.matches("<polyline").count(), 3);
    }
}
