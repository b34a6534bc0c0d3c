// The legend drawn into idms-render's pixels after GL has finished: a panel, the colour bar, ticks
// and text in a 5x7 bitmap font of our own (no font library, no font file at run time: the
// image is the same on every machine).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include "idms/render/display.h"
#include "legend_internal.h"

namespace idms::render {
namespace {

// 5x7 glyphs, rows top first, '#' = ink. '\x01' is "greater or equal", '\x02' "times".
struct Glyph {
  char c;
  std::array<const char*, 7> rows;
};
constexpr Glyph kFont[] = {
    {'0', {".###.", "#...#", "#..##", "#.#.#", "##..#", "#...#", ".###."}},
    {'1', {"..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###."}},
    {'2', {".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####"}},
    {'3', {"#####", "...#.", "..#..", "...#.", "....#", "#...#", ".###."}},
    {'4', {"...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#."}},
    {'5', {"#####", "#....", "####.", "....#", "....#", "#...#", ".###."}},
    {'6', {"..##.", ".#...", "#....", "####.", "#...#", "#...#", ".###."}},
    {'7', {"#####", "....#", "...#.", "..#..", ".#...", ".#...", ".#..."}},
    {'8', {".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###."}},
    {'9', {".###.", "#...#", "#...#", ".####", "....#", "...#.", ".##.."}},
    {'.', {".....", ".....", ".....", ".....", ".....", ".##..", ".##.."}},
    {',', {".....", ".....", ".....", ".....", ".##..", "..#..", ".#..."}},
    {'-', {".....", ".....", ".....", ".###.", ".....", ".....", "....."}},
    {'+', {".....", "..#..", "..#..", "#####", "..#..", "..#..", "....."}},
    {'=', {".....", ".....", "#####", ".....", "#####", ".....", "....."}},
    {'/', {".....", "....#", "...#.", "..#..", ".#...", "#....", "....."}},
    {':', {".....", ".##..", ".##..", ".....", ".##..", ".##..", "....."}},
    {'(', {"...#.", "..#..", ".#...", ".#...", ".#...", "..#..", "...#."}},
    {')', {".#...", "..#..", "...#.", "...#.", "...#.", "..#..", ".#..."}},
    {'\x01', {".#...", "..#..", "...#.", "..#..", ".#...", ".....", "#####"}},
    {'\x02', {".....", "#...#", ".#.#.", "..#..", ".#.#.", "#...#", "....."}},
    {'a', {".....", ".....", ".###.", "....#", ".####", "#...#", ".####"}},
    {'b', {"#....", "#....", "#.##.", "##..#", "#...#", "#...#", "####."}},
    {'c', {".....", ".....", ".###.", "#....", "#....", "#...#", ".###."}},
    {'d', {"....#", "....#", ".##.#", "#..##", "#...#", "#...#", ".####"}},
    {'e', {".....", ".....", ".###.", "#...#", "#####", "#....", ".###."}},
    {'f', {"..##.", ".#..#", ".#...", "###..", ".#...", ".#...", ".#..."}},
    {'g', {".....", ".####", "#...#", "#...#", ".####", "....#", ".###."}},
    {'h', {"#....", "#....", "#.##.", "##..#", "#...#", "#...#", "#...#"}},
    {'i', {"..#..", ".....", ".##..", "..#..", "..#..", "..#..", ".###."}},
    {'j', {"...#.", ".....", "..##.", "...#.", "...#.", "#..#.", ".##.."}},
    {'k', {"#....", "#....", "#..#.", "#.#..", "##...", "#.#..", "#..#."}},
    {'l', {".##..", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."}},
    {'m', {".....", ".....", "##.#.", "#.#.#", "#.#.#", "#...#", "#...#"}},
    {'n', {".....", ".....", "#.##.", "##..#", "#...#", "#...#", "#...#"}},
    {'o', {".....", ".....", ".###.", "#...#", "#...#", "#...#", ".###."}},
    {'p', {".....", ".....", "####.", "#...#", "####.", "#....", "#...."}},
    {'q', {".....", ".....", ".##.#", "#..##", ".####", "....#", "....#"}},
    {'r', {".....", ".....", "#.##.", "##..#", "#....", "#....", "#...."}},
    {'s', {".....", ".....", ".###.", "#....", ".###.", "....#", "####."}},
    {'t', {".#...", ".#...", "###..", ".#...", ".#...", ".#..#", "..##."}},
    {'u', {".....", ".....", "#...#", "#...#", "#...#", "#..##", ".##.#"}},
    {'v', {".....", ".....", "#...#", "#...#", "#...#", ".#.#.", "..#.."}},
    {'w', {".....", ".....", "#...#", "#...#", "#.#.#", "#.#.#", ".#.#."}},
    {'x', {".....", ".....", "#...#", ".#.#.", "..#..", ".#.#.", "#...#"}},
    {'y', {".....", ".....", "#...#", "#...#", ".####", "....#", ".###."}},
    {'z', {".....", ".....", "#####", "...#.", "..#..", ".#...", "#####"}},
};

const Glyph* Find(char c) {
  if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  for (const Glyph& g : kFont) {
    if (g.c == c) return &g;
  }
  return nullptr;  // a space, or a character the font lacks: a blank cell
}

// Blends a rectangle of colour c at opacity a into the image (clipped).
void Fill(Image* im, int x0, int y0, int w, int h, const Srgb& c, double a) {
  for (int y = std::max(0, y0); y < std::min(im->height, y0 + h); ++y) {
    for (int x = std::max(0, x0); x < std::min(im->width, x0 + w); ++x) {
      uint8_t* p = &im->rgba[(static_cast<size_t>(y) * im->width + x) * 4];
      for (int k = 0; k < 3; ++k) p[k] = static_cast<uint8_t>(std::lround(p[k] + (c[k] - p[k]) * a));
    }
  }
}

constexpr Srgb kInk{34, 34, 34};
constexpr Srgb kPanel{255, 255, 255};
constexpr Srgb kBorder{170, 175, 185};

// Text at (x, y) (its top left), each font pixel s x s image pixels; returns its width.
int Text(Image* im, int x, int y, int s, const std::string& text) {
  for (size_t i = 0; i < text.size(); ++i) {
    if (const Glyph* g = Find(text[i])) {
      for (int row = 0; row < 7; ++row) {
        for (int col = 0; col < 5; ++col) {
          if (g->rows[row][col] == '#') Fill(im, x + (6 * static_cast<int>(i) + col) * s, y + row * s, s, s, kInk, 1);
        }
      }
    }
  }
  return TextWidth(text, s);
}

}  // namespace

int TextWidth(const std::string& text, int s) { return static_cast<int>(text.size()) * 6 * s - s; }

std::vector<double> LegendTicks(double lo, double hi, int ticks) {
  if (!(hi - lo > 0)) return {lo};
  std::vector<double> v;
  for (int i = 0; i <= ticks; ++i) v.push_back(lo + (hi - lo) * i / ticks);
  return v;
}

std::string TickText(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

void DrawLegend(const LegendSpec& spec, Image* image) {
  if (image->width < 400 || image->height < 300) return;
  const int s = image->height >= 600 ? 2 : 1;  // font pixel size
  const int pad = 6 * s, line = 10 * s, bar_w = 12 * s, bar_h = std::min(130 * s, image->height / 3);
  const std::vector<double> ticks = LegendTicks(spec.lo, spec.hi, TheDisplay().ticks);
  std::vector<std::string> labels;
  int label_w = 0;
  for (size_t i = 0; i < ticks.size(); ++i) {
    const bool top = i + 1 == ticks.size() && ticks.size() > 1;
    labels.push_back((top && spec.saturates ? "\x01" : "") + TickText(ticks[i]));
    label_w = std::max(label_w, TextWidth(labels.back(), s));
  }
  // The panel: title, unit, bar with its labels, notes.
  int content_w = std::max(TextWidth(spec.title, s), TextWidth(spec.unit, s));
  content_w = std::max(content_w, bar_w + 7 * s + label_w);
  for (const std::string& n : spec.notes) content_w = std::max(content_w, TextWidth(n, s));
  const int panel_w = content_w + 2 * pad;
  const int panel_h = pad + 2 * line + s * 4 + bar_h + 4 * s + static_cast<int>(spec.notes.size()) * line + pad;
  const int x0 = image->width - panel_w - 8 * s, y0 = 8 * s;
  Fill(image, x0, y0, panel_w, panel_h, kPanel, 0.88);
  Fill(image, x0, y0, panel_w, 1, kBorder, 1);
  Fill(image, x0, y0 + panel_h - 1, panel_w, 1, kBorder, 1);
  Fill(image, x0, y0, 1, panel_h, kBorder, 1);
  Fill(image, x0 + panel_w - 1, y0, 1, panel_h, kBorder, 1);
  int y = y0 + pad;
  Text(image, x0 + pad, y, s, spec.title);
  Text(image, x0 + pad, y + line, s, spec.unit);
  // The bar, hi at the top; a tick and its value at each step.
  const int bar_x = x0 + pad, bar_y = y + 2 * line + 4 * s;
  const auto& map = TheDisplay().map;
  for (int r = 0; r < bar_h; ++r) {
    const int index = static_cast<int>(std::lround(255.0 * (bar_h - 1 - r) / (bar_h - 1)));
    Fill(image, bar_x, bar_y + r, bar_w, 1, map[static_cast<size_t>(index)], 1);
  }
  for (size_t i = 0; i < ticks.size(); ++i) {
    const double f = ticks.size() > 1 ? static_cast<double>(i) / static_cast<double>(ticks.size() - 1) : 0;
    const int ty = bar_y + static_cast<int>(std::lround((1 - f) * (bar_h - 1)));
    Fill(image, bar_x + bar_w, ty, 3 * s, s, kInk, 1);
    Text(image, bar_x + bar_w + 7 * s, ty - 3 * s, s, labels[i]);
  }
  y = bar_y + bar_h + 4 * s + 2 * s;
  for (const std::string& n : spec.notes) {
    Text(image, x0 + pad, y, s, n);
    y += line;
  }
}

}  // namespace idms::render
