// The colour legend idms-render draws over its image (the browser's is HTML, viewer-web's
// view/legend.js, with the same lines): a bar of the colour map with ticks and their values, the
// unit, the deformation scale when it is not 1, and when rest is not the session's start.
#pragma once

#include <string>
#include <vector>

#include "idms/render/render.h"

namespace idms::render {

struct LegendSpec {
  std::string title;               // "displacement" or "stiffness"
  std::string unit;                // "model units", ...
  double lo = 0, hi = 1;           // the range the map spans
  bool saturates = false;          // values beyond hi take its colour: the top label says ">="
  std::vector<std::string> notes;  // further lines under the bar ("deformation x3", ...)
};

// The legend's tick values, lo to hi in `ticks` equal steps (a range of zero width: lo alone).
std::vector<double> LegendTicks(double lo, double hi, int ticks);
// A tick's text: at most 3 significant digits, no trailing zeros ("0.025", "120", "0").
std::string TickText(double v);

// The width in pixels of a line of text at font pixel size s.
int TextWidth(const std::string& text, int s);

// Draws the legend into the image's top right corner, scaled to its height (nothing below
// 400x300 pixels: a thumbnail). Pixels only: no GL.
void DrawLegend(const LegendSpec& spec, Image* image);

}  // namespace idms::render
