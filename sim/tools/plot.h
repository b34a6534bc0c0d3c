// PNG plots for idms-sim (root loci, `run --plot`, bench curves): a generated gnuplot script run
// as a subprocess with the pngcairo terminal. Tool-side only; libidms_sim never plots.
#pragma once

#include <array>
#include <optional>
#include <string>
#include <vector>

namespace idms::tool {

// One curve, from columns of a CSV file (first line a header of column names) or inline points.
struct PlotSeries {
  std::string title;                          // legend entry; empty = not in the legend
  std::string csv_path;                       // comma-separated data; empty when `points` is used
  std::string x_column, y_column;             // header names in csv_path
  std::string color_column;                   // optional: colour by this column through the palette
  std::string label_column;                   // optional: print this column as text at each point
  std::vector<std::array<double, 2>> points;  // inline (x, y) data instead of a file
  std::string style = "lines";                // gnuplot style: lines, points, linespoints, dots
  std::string options;                        // appended after the style, e.g. "pt 2 ps 2 lc rgb 'black'"
};

struct PlotSpec {
  std::string title, x_label, y_label;
  std::string color_label;  // colour-box label, for series with a color_column
  int width_px = 900, height_px = 800;
  bool equal_aspect = false;  // one unit on x is as long as one on y (z-plane plots)
  bool log_x = false, log_y = false;
  std::optional<std::array<double, 2>> x_range, y_range;
  std::string key = "top left";       // gnuplot `set key` argument; "off" hides the legend
  std::vector<std::string> preamble;  // raw gnuplot commands, after the defaults and before `plot`
  std::vector<PlotSeries> series;
};

// Writes `png_path` from `spec` by running gnuplot ($IDMS_GNUPLOT, else `gnuplot` on PATH) on a
// temporary script; blocks until it exits. Returns false with a one-line reason in *error when
// gnuplot is missing or fails, a CSV or column is missing, or no PNG appears. Allocates and
// spawns a process; never for the 1 kHz loop.
bool PlotPng(const PlotSpec& spec, const std::string& png_path, std::string* error);

}  // namespace idms::tool
