#include "unsup_mvs/io/loss_curve.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>

namespace umvs {

namespace {

// 3x5 glyphs for the axis labels: rows top to bottom, 3 bits each (MSB = left).
const char* kGlyphChars = "0123456789.-e+";
const uint8_t kGlyphs[][5] = {
    {7, 5, 5, 5, 7}, {2, 6, 2, 2, 7}, {7, 1, 7, 4, 7}, {7, 1, 7, 1, 7}, {5, 5, 7, 1, 1},
    {7, 4, 7, 1, 7}, {7, 4, 7, 5, 7}, {7, 1, 1, 1, 1}, {7, 5, 7, 5, 7}, {7, 5, 7, 1, 7},
    {0, 0, 0, 0, 2}, {0, 0, 7, 0, 0}, {0, 7, 5, 6, 7}, {0, 2, 7, 2, 0},
};

void draw_text(torch::TensorAccessor<uint8_t, 3>& img, int x, int y, const std::string& text, int scale = 2) {
  const int H = img.size(0), W = img.size(1);
  for (char ch : text) {
    const char* p = std::strchr(kGlyphChars, ch);
    if (p != nullptr && ch != '\0') {
      const auto& g = kGlyphs[p - kGlyphChars];
      for (int r = 0; r < 5; ++r)
        for (int c = 0; c < 3; ++c)
          if (g[r] & (4 >> c))
            for (int dy = 0; dy < scale; ++dy)
              for (int dx = 0; dx < scale; ++dx) {
                const int yy = y + r * scale + dy, xx = x + c * scale + dx;
                if (yy >= 0 && yy < H && xx >= 0 && xx < W)
                  for (int k = 0; k < 3; ++k) img[yy][xx][k] = 0;
              }
    }
    x += 4 * scale;
  }
}

}  // namespace

torch::Tensor render_curves(const std::vector<CurveSeries>& series, int width, int height) {
  auto img = torch::full({height, width, 3}, 255, torch::kUInt8);
  auto a = img.accessor<uint8_t, 3>();
  double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
  for (const auto& s : series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i]) || s.y[i] <= 0) continue;
      x0 = std::min(x0, s.x[i]);
      x1 = std::max(x1, s.x[i]);
      y0 = std::min(y0, std::log10(s.y[i]));
      y1 = std::max(y1, std::log10(s.y[i]));
    }
  if (!std::isfinite(x0)) return img;
  if (x1 <= x0) x1 = x0 + 1;
  if (y1 - y0 < 1e-3) y0 -= 0.05, y1 += 0.05;
  const int left = 60, right = width - 10, top = 10, bottom = height - 20;
  auto px = [&](double x) { return left + (x - x0) / (x1 - x0) * (right - left); };
  auto py = [&](double ly) { return bottom - (ly - y0) / (y1 - y0) * (bottom - top); };
  auto put = [&](int x, int y, uint8_t r, uint8_t g, uint8_t b) {
    if (x >= 0 && x < width && y >= 0 && y < height) a[y][x][0] = r, a[y][x][1] = g, a[y][x][2] = b;
  };
  for (int p = static_cast<int>(std::floor(y0)); p <= static_cast<int>(std::ceil(y1)); ++p)  // decades
    for (int d = 1; d < 10; ++d) {
      const double ly = p + std::log10(static_cast<double>(d));
      if (ly < y0 || ly > y1) continue;
      const int y = static_cast<int>(std::lround(py(ly)));
      const uint8_t shade = d == 1 ? 170 : 225;
      for (int x = left; x <= right; ++x) put(x, y, shade, shade, shade);
    }
  for (int y = top; y <= bottom; ++y) put(left, y, 0, 0, 0);
  for (int x = left; x <= right; ++x) put(x, bottom, 0, 0, 0);
  for (const auto& s : series) {
    bool have = false;
    double lx = 0, ly = 0;
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!std::isfinite(s.y[i]) || s.y[i] <= 0) continue;
      const double cx = px(s.x[i]), cy = py(std::log10(s.y[i]));
      if (have) {
        const int n = static_cast<int>(std::max(std::abs(cx - lx), std::abs(cy - ly))) + 1;
        for (int k = 0; k <= n; ++k) {
          const int x = static_cast<int>(std::lround(lx + (cx - lx) * k / n));
          const int y = static_cast<int>(std::lround(ly + (cy - ly) * k / n));
          put(x, y, s.r, s.g, s.b);
          put(x, y + 1, s.r, s.g, s.b);
        }
      } else {
        put(static_cast<int>(cx), static_cast<int>(cy), s.r, s.g, s.b);
      }
      have = true;
      lx = cx, ly = cy;
    }
  }
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3g", std::pow(10.0, y1));
  draw_text(a, 2, top, buf);
  std::snprintf(buf, sizeof(buf), "%.3g", std::pow(10.0, y0));
  draw_text(a, 2, bottom - 10, buf);
  std::snprintf(buf, sizeof(buf), "%.0f", x0);
  draw_text(a, left, bottom + 5, buf);
  std::snprintf(buf, sizeof(buf), "%.0f", x1);
  draw_text(a, right - 8 * static_cast<int>(std::strlen(buf)), bottom + 5, buf);
  return img;
}

}  // namespace umvs
