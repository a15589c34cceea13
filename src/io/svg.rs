//! Line charts as SVG text (the figures `bench pem-lobes` and `btf compress` write into docs/):
//! the frame, the axis titles and each series with its legend entry; the callers draw their
//! own grids and ticks, linear or logarithmic.

use std::fmt::Write as _;

/// A chart `width` x `height` with the plot area inside the margins; the legend sits in the
/// right margin.
pub struct Chart {
    pub width: f64,
    pub height: f64,
    pub left: f64,
    pub right: f64,
    pub top: f64,
    pub bottom: f64,
}

impl Chart {
    /// The opening tag, a white background and the title centred over the plot area.
    pub fn open(&self, title: &str) -> String {
        let (w, h) = (self.width, self.height);
        format!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\" font-family=\"sans-serif\" font-size=\"12\">\n<rect width=\"{w}\" height=\"{h}\" fill=\"white\"/>\n<text x=\"{:.1}\" y=\"22\" text-anchor=\"middle\" font-size=\"14\">{title}</text>\n",
            self.centre_x()
        )
    }

    /// The x axis's title under the plot and the y axis's turned along the left edge.
    pub fn axis_titles(&self, x_title: &str, y_title: &str) -> String {
        let mid_y = (self.top + self.height - self.bottom) / 2.0;
        format!(
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{x_title}</text>\n<text x=\"16\" y=\"{mid_y:.1}\" text-anchor=\"middle\" transform=\"rotate(-90 16 {mid_y:.1})\">{y_title}</text>\n",
            self.centre_x(),
            self.height - 12.0
        )
    }

    /// Series `index` (its legend row) as a polyline through `points` (chart coordinates), in
    /// `colour`, dashed by `dash` (an SVG `stroke-dasharray` value, or empty).
    pub fn series(
        &self,
        index: usize,
        name: &str,
        colour: &str,
        dash: &str,
        points: impl IntoIterator<Item = (f64, f64)>,
    ) -> String {
        let dash = if dash.is_empty() { String::new() } else { format!(" stroke-dasharray=\"{dash}\"") };
        let mut line = String::new();
        for (i, (x, y)) in points.into_iter().enumerate() {
            let _ = write!(line, "{}{x:.1},{y:.1}", if i == 0 { "" } else { " " });
        }
        let ly = self.top + 10.0 + 20.0 * index as f64;
        let lx = self.width - self.right;
        format!(
            "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"2\"{dash} points=\"{line}\"/>\n<line x1=\"{:.1}\" y1=\"{ly:.1}\" x2=\"{:.1}\" y2=\"{ly:.1}\" stroke=\"{colour}\" stroke-width=\"2\"{dash}/><text x=\"{:.1}\" y=\"{:.1}\">{name}</text>\n",
            lx + 10.0,
            lx + 36.0,
            lx + 42.0,
            ly + 4.0
        )
    }

    fn centre_x(&self) -> f64 {
        (self.left + self.width - self.right) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_series_is_its_points_and_a_legend_row() {
        let chart = Chart { width: 100.0, height: 80.0, left: 10.0, right: 30.0, top: 5.0, bottom: 5.0 };
        let s = chart.series(1, "b", "#000", "3 3", [(1.0, 2.0), (3.25, 4.0)]);
        assert!(s.contains("points=\"1.0,2.0 3.2,4.0\""), "{s}");
        assert!(s.contains("stroke-dasharray=\"3 3\""), "{s}");
        // Legend row 1: 20 px below row 0, right of the plot area.
        assert!(s.contains("y1=\"35.0\"") && s.contains("x1=\"80.0\"") && s.contains(">b</text>"), "{s}");
        assert!(!chart.series(0, "a", "#000", "", [(0.0, 0.0)]).contains("dasharray"));
    }
}
