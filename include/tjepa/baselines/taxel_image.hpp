#pragma once
// Tactile images: one frame of a skin drawn as a multi-channel picture, the input of an image
// encoder such as BYOL's AlexNet (T-DEX, Guzey et al. 2023, the paper's BYOL baseline; the
// Tactile-JEPA reference code's XelaBYOLDataset and its tactile augmentations).
//
//   TaxelCanvas   where each taxel sits on an H × W canvas (one pixel per taxel, zeros elsewhere):
//                   tdex_allegro   T-DEX's 26 × 24 picture of the Allegro hand's 18 Xela pads
//                   from_cells     any skin with grid cells: its pads side by side, row by row
//                   from_coordinates any 2-D skin: its coordinates on a grid of its taxel pitch
//   TaxelImager   frame [N, A] → canvas [H, W, A] → S × S (PyTorch's antialiased bilinear
//                 resize) → clamp to ±range, (x + range) / 2·range ∈ [0, 1]; for training, T-DEX's
//                 augmentations, each with probability 0.5 and drawn per image:
//                   RandomResizedCrop(S, scale [0.9, 1], ratio [3/4, 4/3])   (torchvision's draw)
//                   GaussianBlur(3 × 3, σ ~ U(1, 2))                          (reflect padding)
//                 then per-channel normalization (ImageNet's statistics for 3 channels, as the
//                 reference, which trains on pretrained AlexNet statistics).
// Images are NHWC [S, S, A], float; A = the skin's axes (x, y, z for Xela: the reference's RGB).
//
// The reference normalizes the augmented training views only and embeds un-normalized images;
// here embeddings go through the same normalization as training (the network sees one input
// distribution). Its range is ±500 raw counts; windows that are already standardized per axis
// take a range in standard deviations (ByolConfig, baselines/byol.hpp).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <set>
#include <span>
#include <string>
#include <vector>

#include "tjepa/core/aligned.hpp"
#include "tjepa/core/error.hpp"
#include "tjepa/core/random.hpp"
#include "tjepa/layout/taxel_layout.hpp"
#include "tjepa/sensors/allegro_xela.hpp"

namespace tjepa {

struct TaxelCanvas {
  int height = 0, width = 0;
  std::vector<int> pixel;  // [N] taxel n sits at y·width + x; no two taxels share a pixel

  int taxels() const { return static_cast<int>(pixel.size()); }

  // Throws unless it places `taxels` taxels on distinct pixels inside the canvas.
  void validate(int taxels_expected) const {
    require<ShapeError>(height > 0 && width > 0, "TaxelCanvas: ", height, " x ", width, ", expected > 0");
    require<ShapeError>(taxels() == taxels_expected, "TaxelCanvas: places ", taxels(), " taxels, the data has ",
                        taxels_expected);
    std::vector<int> owner(std::size_t(height) * std::size_t(width), -1);
    for (int n = 0; n < taxels(); ++n) {
      const int p = pixel[std::size_t(n)];
      require<ShapeError>(p >= 0 && p < height * width, "TaxelCanvas: taxel ", n, " at pixel ", p, ", outside the ",
                          height, " x ", width, " canvas");
      require<ShapeError>(owner[std::size_t(p)] < 0, "TaxelCanvas: taxels ", owner[std::size_t(p)], " and ", n,
                          " share pixel (", p / width, ", ", p % width, ")");
      owner[std::size_t(p)] = n;
    }
  }

  // T-DEX's picture of the Allegro hand (the reference's XELA_IMG_ORDER and xela_flat_to_grid):
  // 26 × 24; a fingertip's 6 × 6 with its dome rows on top, a phalanx pad's 4 × 4 two columns in,
  // a palm pad's 4 × 6. The layout must be layouts::allegro_xela()'s (pads and cells).
  static TaxelCanvas tdex_allegro(const TaxelLayout& layout) {
    namespace xa = layouts::allegro;
    require<ConfigError>(layout.size() == xa::kTaxels && layout.group_names == xa::pad_names() && layout.has_cells(),
                         "TaxelCanvas::tdex_allegro: the layout has ", layout.size(), " taxels in ",
                         layout.num_groups(), " pads", layout.has_cells() ? "" : " without cells",
                         ", expected the Allegro hand's ", xa::kTaxels, " in its ", xa::kPads, " named pads");
    // Top-left corner of each pad's 6-wide slot, in tjepa's pad order (which is the reference's).
    static constexpr std::array<std::array<int, 2>, 18> origin{{{4, 0},  {10, 0}, {14, 0},                    // thumb
                                                                 {0, 6},  {6, 6},  {10, 6},  {14, 6},        // index
                                                                 {0, 12}, {6, 12}, {10, 12}, {14, 12},       // middle
                                                                 {0, 18}, {6, 18}, {10, 18}, {14, 18},       // ring
                                                                 {18, 6}, {18, 12}, {22, 12}}};              // palm
    TaxelCanvas c{26, 24, std::vector<int>(std::size_t(layout.size()))};
    for (int n = 0; n < layout.size(); ++n) {
      const int g = layout.group[std::size_t(n)], r = layout.row[std::size_t(n)], col = layout.col[std::size_t(n)];
      const bool tip = g == 0 || g == 3 || g == 7 || g == 11, palm = g >= 15;
      const int y = origin[std::size_t(g)][0] + (tip ? 5 - r : r);
      const int x = origin[std::size_t(g)][1] + (tip || palm ? col : col + 2);
      c.pixel[std::size_t(n)] = y * c.width + x;
    }
    c.validate(layout.size());
    return c;
  }

  // Any skin with cells. Cells that are unique within each part (a sheet whose pads share one
  // grid) keep the part's picture; cells that repeat across a part's pads (each pad its own grid,
  // as the hand's) give each pad its own picture. The pictures (bounding boxes of their cells) are
  // placed left to right in rows of about √(total area) pixels, in order, without gaps (as T-DEX's).
  static TaxelCanvas from_cells(const TaxelLayout& layout) {
    require<ConfigError>(layout.has_cells(), "TaxelCanvas::from_cells: the layout has no grid cells (row, col)");
    const int N = layout.size();
    for (int n = 0; n < N; ++n)
      require<ConfigError>(layout.row[std::size_t(n)] >= 0 && layout.col[std::size_t(n)] >= 0,
                           "TaxelCanvas::from_cells: taxel ", n, " (pad '",
                           layout.group_names[std::size_t(layout.group[std::size_t(n)])], "') has no cell");
    std::set<std::array<int, 3>> seen;
    bool per_part = true;
    for (int n = 0; n < N && per_part; ++n)
      per_part = seen.insert({layout.part[std::size_t(n)], layout.row[std::size_t(n)], layout.col[std::size_t(n)]}).second;
    const std::vector<int>& unit = per_part ? layout.part : layout.group;
    const int U = per_part ? layout.num_parts() : layout.num_groups();
    const int big = std::numeric_limits<int>::max();
    std::vector<int> r0(std::size_t(U), big), c0(std::size_t(U), big), r1(std::size_t(U), -1), c1(std::size_t(U), -1);
    for (int n = 0; n < N; ++n) {
      const std::size_t u = std::size_t(unit[std::size_t(n)]);
      r0[u] = std::min(r0[u], layout.row[std::size_t(n)]), r1[u] = std::max(r1[u], layout.row[std::size_t(n)]);
      c0[u] = std::min(c0[u], layout.col[std::size_t(n)]), c1[u] = std::max(c1[u], layout.col[std::size_t(n)]);
    }
    double area = 0;
    int widest = 1;
    for (int u = 0; u < U; ++u)
      if (r1[std::size_t(u)] >= 0) {
        const int w = c1[std::size_t(u)] - c0[std::size_t(u)] + 1;
        area += double(r1[std::size_t(u)] - r0[std::size_t(u)] + 1) * w, widest = std::max(widest, w);
      }
    const int limit = std::max(widest, static_cast<int>(std::ceil(std::sqrt(area))));
    std::vector<int> top(static_cast<std::size_t>(U)), left(static_cast<std::size_t>(U));
    int x = 0, y = 0, shelf = 0, width = 0;
    for (int u = 0; u < U; ++u) {
      if (r1[std::size_t(u)] < 0) continue;  // a pad without taxels
      const int w = c1[std::size_t(u)] - c0[std::size_t(u)] + 1, h = r1[std::size_t(u)] - r0[std::size_t(u)] + 1;
      if (x > 0 && x + w > limit) y += shelf, x = 0, shelf = 0;
      top[std::size_t(u)] = y - r0[std::size_t(u)], left[std::size_t(u)] = x - c0[std::size_t(u)];
      x += w;
      shelf = std::max(shelf, h);
      width = std::max(width, x);
    }
    TaxelCanvas c{y + shelf, width, std::vector<int>(std::size_t(N))};
    for (int n = 0; n < N; ++n) {
      const std::size_t u = std::size_t(unit[std::size_t(n)]);
      c.pixel[std::size_t(n)] = (top[u] + layout.row[std::size_t(n)]) * c.width + left[u] + layout.col[std::size_t(n)];
    }
    c.validate(N);
    return c;
  }

  // Any skin with 2-D coordinates: x right, y up, on a grid of `pitch` mm (0: the median distance
  // of a taxel to its nearest neighbour). A taxel whose pixel is taken moves to the nearest free
  // pixel at most 2 pixels away (rings of growing radius, row-major within a ring); where none is
  // free, the grid is refined. Every taxel keeps its own pixel.
  static TaxelCanvas from_coordinates(const TaxelLayout& layout, double pitch = 0) {
    require<ConfigError>(layout.dim == 2, "TaxelCanvas::from_coordinates: the layout has ", layout.dim,
                         "-D coordinates, expected 2-D");
    const int N = layout.size();
    auto at = [&](int n, int k) { return layout.coords[std::size_t(n) * 2 + std::size_t(k)]; };
    if (pitch <= 0) {
      std::vector<double> nearest;
      for (int i = 0; i < N; ++i) {
        double best = std::numeric_limits<double>::infinity();
        for (int j = 0; j < N; ++j)
          if (j != i) best = std::min(best, std::hypot(at(i, 0) - at(j, 0), at(i, 1) - at(j, 1)));
        if (std::isfinite(best) && best > 0) nearest.push_back(best);
      }
      require<ConfigError>(!nearest.empty(), "TaxelCanvas::from_coordinates: no two taxels apart, no pitch to find");
      std::nth_element(nearest.begin(), nearest.begin() + std::ptrdiff_t(nearest.size() / 2), nearest.end());
      pitch = nearest[nearest.size() / 2];
    }
    require<ConfigError>(std::isfinite(pitch) && pitch > 0, "TaxelCanvas::from_coordinates: pitch = ", pitch,
                         ", expected > 0");
    double x0 = std::numeric_limits<double>::infinity(), y1 = -x0, x1 = -x0, y0 = x0;
    for (int n = 0; n < N; ++n)
      x0 = std::min(x0, at(n, 0)), x1 = std::max(x1, at(n, 0)), y0 = std::min(y0, at(n, 1)), y1 = std::max(y1, at(n, 1));
    // More taxels than pixels near them: the grid is refined (pitch × 0.9) until all fit.
    for (;; pitch *= 0.9) {
      const double cells = ((x1 - x0) / pitch + 1) * ((y1 - y0) / pitch + 1);
      require<ConfigError>(cells < 4e6, "TaxelCanvas::from_coordinates: a ", (x1 - x0), " x ", (y1 - y0),
                           " mm skin at pitch ", pitch, " mm is more than 4 million pixels");
      TaxelCanvas c;
      c.width = static_cast<int>(std::lround((x1 - x0) / pitch)) + 1;
      c.height = static_cast<int>(std::lround((y1 - y0) / pitch)) + 1;
      if (std::size_t(c.width) * std::size_t(c.height) < std::size_t(N)) continue;
      std::vector<int> owner(std::size_t(c.height) * std::size_t(c.width), -1);
      c.pixel.resize(std::size_t(N));
      const int reach = 2;  // rings searched around a taxel's own pixel
      bool placed = true;
      for (int n = 0; n < N && placed; ++n) {
        const int x = static_cast<int>(std::lround((at(n, 0) - x0) / pitch));
        const int y = static_cast<int>(std::lround((y1 - at(n, 1)) / pitch));  // image rows go down
        int p = -1;
        for (int radius = 0; p < 0 && radius <= reach; ++radius)
          for (int dy = -radius; dy <= radius && p < 0; ++dy)
            for (int dx = -radius; dx <= radius && p < 0; ++dx) {
              if (std::max(std::abs(dx), std::abs(dy)) != radius) continue;
              const int yy = y + dy, xx = x + dx;
              if (yy >= 0 && yy < c.height && xx >= 0 && xx < c.width && owner[std::size_t(yy * c.width + xx)] < 0)
                p = yy * c.width + xx;
            }
        placed = p >= 0;
        if (placed) owner[std::size_t(p)] = n, c.pixel[std::size_t(n)] = p;
      }
      if (placed) return c;
    }
  }

  // The canvas a skin gets by default: T-DEX's for the Allegro hand, else its cells, else its 2-D
  // coordinates.
  static TaxelCanvas from_layout(const TaxelLayout& layout) {
    if (layout.size() == layouts::allegro::kTaxels && layout.group_names == layouts::allegro::pad_names() &&
        layout.has_cells())
      return tdex_allegro(layout);
    if (layout.has_cells()) {
      bool all = true;
      for (int n = 0; n < layout.size(); ++n) all = all && layout.row[std::size_t(n)] >= 0;
      if (all) return from_cells(layout);
    }
    if (layout.dim == 2) return from_coordinates(layout);
    fail<ConfigError>("TaxelCanvas: the layout has neither grid cells for every taxel nor 2-D coordinates (it has ",
                      layout.dim, "-D ones); an image encoder needs one of them to draw the skin");
  }
};

// PyTorch's antialiased bilinear resampling along one axis (interpolate(..., mode="bilinear",
// antialias=True), align_corners=False): output i reads input [first[i], first[i] + count) with
// weights w (a triangle of width max(1, in/out) each side, normalized). For upsampling this is
// plain bilinear with clamped edges.
struct ResampleAxis {
  int out = 0, span = 0;  // weights per output: span (the widest)
  std::vector<int> first, count;
  std::vector<float> weight;  // [out, span]

  ResampleAxis() = default;
  // Input [start, start + length) (a crop, in pixels of the input axis) → out samples.
  ResampleAxis(double start, double length, int input_size, int out_size) : out(out_size) {
    const double scale = length / out_size;
    const double support = scale >= 1 ? scale : 1.0, inv = scale >= 1 ? 1.0 / scale : 1.0;
    span = static_cast<int>(std::ceil(support)) * 2 + 1;
    first.resize(std::size_t(out)), count.resize(std::size_t(out));
    weight.assign(std::size_t(out) * std::size_t(span), 0.f);
    const int lo = static_cast<int>(std::floor(start)), hi = static_cast<int>(std::ceil(start + length));
    std::vector<double> w(static_cast<std::size_t>(span));  // one output's taps: at most 2·support + 1 <= span
    for (int i = 0; i < out; ++i) {
      const double center = scale * (i + 0.5);  // in crop coordinates
      const int xmin = std::max(static_cast<int>(center - support + 0.5), 0);
      const int xmax = std::min(static_cast<int>(center + support + 0.5), hi - lo);
      const int taps = std::max(xmax - xmin, 0);
      require<ShapeError>(taps <= span, "ResampleAxis: ", taps, " taps, room for ", span);
      double total = 0;
      for (int j = xmin; j < xmax; ++j) {
        const double t = std::abs((j - center + 0.5) * inv);
        w[std::size_t(j - xmin)] = t < 1 ? 1 - t : 0;
        total += w[std::size_t(j - xmin)];
      }
      first[std::size_t(i)] = std::clamp(lo + xmin, 0, input_size - 1);
      count[std::size_t(i)] = std::min<int>(taps, input_size - first[std::size_t(i)]);
      for (int k = 0; k < count[std::size_t(i)]; ++k)
        weight[std::size_t(i) * std::size_t(span) + std::size_t(k)] = total > 0 ? float(w[std::size_t(k)] / total) : 0.f;
    }
  }
};

// dst [oh, ow, A] = src [h, w, A] (row stride w·A) resampled along rows then columns.
inline void resample_image(float* dst, const float* src, int w, int A, const ResampleAxis& ry, const ResampleAxis& rx,
                           std::vector<float>& tmp) {
  // Columns first: tmp [rows touched, ow, A] for every source row ry reads.
  const int ow = rx.out, oh = ry.out;
  int r0 = std::numeric_limits<int>::max(), r1 = 0;
  for (int i = 0; i < oh; ++i) r0 = std::min(r0, ry.first[std::size_t(i)]), r1 = std::max(r1, ry.first[std::size_t(i)] + ry.count[std::size_t(i)]);
  tmp.assign(std::size_t(r1 - r0) * std::size_t(ow) * std::size_t(A), 0.f);
  for (int y = r0; y < r1; ++y)
    for (int j = 0; j < ow; ++j) {
      float* t = tmp.data() + (std::size_t(y - r0) * ow + std::size_t(j)) * std::size_t(A);
      const float* wj = rx.weight.data() + std::size_t(j) * std::size_t(rx.span);
      for (int k = 0; k < rx.count[std::size_t(j)]; ++k) {
        const float* s = src + (std::size_t(y) * std::size_t(w) + std::size_t(rx.first[std::size_t(j)] + k)) * std::size_t(A);
        for (int a = 0; a < A; ++a) t[a] += wj[k] * s[a];
      }
    }
  for (int i = 0; i < oh; ++i) {
    float* d = dst + std::size_t(i) * std::size_t(ow) * std::size_t(A);
    std::fill(d, d + std::size_t(ow) * std::size_t(A), 0.f);
    const float* wi = ry.weight.data() + std::size_t(i) * std::size_t(ry.span);
    for (int k = 0; k < ry.count[std::size_t(i)]; ++k) {
      const float* t = tmp.data() + std::size_t(ry.first[std::size_t(i)] + k - r0) * std::size_t(ow) * std::size_t(A);
      for (std::size_t q = 0; q < std::size_t(ow) * std::size_t(A); ++q) d[q] += wi[k] * t[q];
    }
  }
}

// torchvision's RandomResizedCrop.get_params: a crop (top, left, height, width) of an h × w image
// covering U(scale) of its area with aspect ratio exp(U(log ratio)), 10 tries, else the central
// crop of the nearest admissible ratio.
struct CropBox {
  int top = 0, left = 0, height = 0, width = 0;
};
inline CropBox random_resized_crop(Rng& rng, int h, int w, std::array<double, 2> scale, std::array<double, 2> ratio) {
  const double area = double(h) * w, lr0 = std::log(ratio[0]), lr1 = std::log(ratio[1]);
  for (int attempt = 0; attempt < 10; ++attempt) {
    const double target = area * rng.uniform(scale[0], scale[1]);
    const double aspect = std::exp(rng.uniform(lr0, lr1));
    const int cw = static_cast<int>(std::lround(std::sqrt(target * aspect)));
    const int ch = static_cast<int>(std::lround(std::sqrt(target / aspect)));
    if (cw > 0 && cw <= w && ch > 0 && ch <= h) {
      const int top = static_cast<int>(rng.below(std::uint64_t(h - ch + 1)));
      const int left = static_cast<int>(rng.below(std::uint64_t(w - cw + 1)));
      return {top, left, ch, cw};
    }
  }
  const double in_ratio = double(w) / h;
  int cw = w, ch = h;
  if (in_ratio < ratio[0])
    ch = static_cast<int>(std::lround(cw / ratio[0]));
  else if (in_ratio > ratio[1])
    cw = static_cast<int>(std::lround(ch * ratio[1]));
  return {(h - ch) / 2, (w - cw) / 2, ch, cw};
}

// torchvision's gaussian_blur with a 3 × 3 kernel of σ (both axes), reflect padding, in place on
// img [h, w, A].
inline void gaussian_blur3(float* img, int h, int w, int A, double sigma, std::vector<float>& tmp) {
  const double e = std::exp(-0.5 / (sigma * sigma));
  const float k0 = float(1.0 / (1.0 + 2.0 * e)), k1 = float(e / (1.0 + 2.0 * e));  // centre, sides
  auto reflect = [](int i, int n) { return i < 0 ? std::min(-i, n - 1) : (i >= n ? std::max(2 * n - 2 - i, 0) : i); };
  const std::size_t row = std::size_t(w) * std::size_t(A);
  tmp.resize(std::size_t(h) * row);
  for (int y = 0; y < h; ++y)  // horizontal pass into tmp
    for (int x = 0; x < w; ++x) {
      const float* l = img + std::size_t(y) * row + std::size_t(reflect(x - 1, w)) * std::size_t(A);
      const float* c = img + std::size_t(y) * row + std::size_t(x) * std::size_t(A);
      const float* r = img + std::size_t(y) * row + std::size_t(reflect(x + 1, w)) * std::size_t(A);
      float* t = tmp.data() + std::size_t(y) * row + std::size_t(x) * std::size_t(A);
      for (int a = 0; a < A; ++a) t[a] = k1 * l[a] + k0 * c[a] + k1 * r[a];
    }
  for (int y = 0; y < h; ++y) {  // vertical pass back into img
    const float* u = tmp.data() + std::size_t(reflect(y - 1, h)) * row;
    const float* c = tmp.data() + std::size_t(y) * row;
    const float* d = tmp.data() + std::size_t(reflect(y + 1, h)) * row;
    float* o = img + std::size_t(y) * row;
    for (std::size_t q = 0; q < row; ++q) o[q] = k1 * u[q] + k0 * c[q] + k1 * d[q];
  }
}

struct TaxelImageConfig {
  int image_size = 224;            // S
  double range = 500;              // values clamped to ±range, then mapped to [0, 1]
  double crop_probability = 0.5;   // RandomResizedCrop
  std::array<double, 2> crop_scale{0.9, 1.0}, crop_ratio{3.0 / 4.0, 4.0 / 3.0};
  double blur_probability = 0.5;   // GaussianBlur 3 × 3
  std::array<double, 2> blur_sigma{1.0, 2.0};
  std::vector<double> mean{0.485, 0.456, 0.406}, std{0.229, 0.224, 0.225};  // per channel; 1 value: all channels

  void validate(int channels) const {
    require<ConfigError>(image_size >= 1 && std::isfinite(range) && range > 0, "TaxelImageConfig: image_size ",
                         image_size, ", range ", range, ", expected >= 1 and > 0");
    for (double p : {crop_probability, blur_probability})
      require<ConfigError>(p >= 0 && p <= 1, "TaxelImageConfig: probability ", p, ", expected in [0, 1]");
    require<ConfigError>(crop_scale[0] > 0 && crop_scale[0] <= crop_scale[1] && crop_scale[1] <= 1 && crop_ratio[0] > 0 &&
                             crop_ratio[0] <= crop_ratio[1] && blur_sigma[0] > 0 && blur_sigma[0] <= blur_sigma[1],
                         "TaxelImageConfig: crop scale [", crop_scale[0], ", ", crop_scale[1], "], ratio [", crop_ratio[0],
                         ", ", crop_ratio[1], "], blur sigma [", blur_sigma[0], ", ", blur_sigma[1],
                         "], expected 0 < lo <= hi (scale <= 1)");
    for (const auto* v : {&mean, &std})
      require<ConfigError>(v->size() == 1 || v->size() == std::size_t(channels), "TaxelImageConfig: ", v->size(),
                           " normalization values for ", channels, " channels, expected 1 or ", channels);
    for (double s : std) require<ConfigError>(s > 0, "TaxelImageConfig: std ", s, ", expected > 0");
  }
  // The normalization of a skin with `channels` axes: ImageNet's for 3, their means otherwise.
  static TaxelImageConfig for_channels(int channels) {
    TaxelImageConfig c;
    if (channels != 3) c.mean = {0.449}, c.std = {0.226};
    return c;
  }
};

// Frames of a skin → normalized S × S images. Not thread-safe (scratch buffers); one per thread.
class TaxelImager {
 public:
  TaxelImager(TaxelCanvas canvas, int channels, TaxelImageConfig config)
      : canvas_(std::move(canvas)), A_(channels), c_(std::move(config)) {
    require<ConfigError>(channels > 0, "TaxelImager: channels = ", channels, ", expected > 0");
    c_.validate(channels);
    canvas_.validate(canvas_.taxels());
    const int S = c_.image_size;
    full_y_ = ResampleAxis(0, canvas_.height, canvas_.height, S);
    full_x_ = ResampleAxis(0, canvas_.width, canvas_.width, S);
  }

  const TaxelCanvas& canvas() const { return canvas_; }
  const TaxelImageConfig& config() const { return c_; }
  int channels() const { return A_; }
  int image_size() const { return c_.image_size; }
  std::size_t image_values() const { return std::size_t(c_.image_size) * std::size_t(c_.image_size) * std::size_t(A_); }

  // frame: taxel n's A values at frame[n·stride + a·axis_stride]. out [S, S, A]. rng: the
  // augmentations' draws (nullptr: none, as for embedding).
  void image(float* out, const float* frame, std::size_t stride, std::size_t axis_stride, Rng* rng) {
    const int H = canvas_.height, W = canvas_.width, S = c_.image_size;
    canvas_values_.assign(std::size_t(H) * std::size_t(W) * std::size_t(A_), 0.f);
    for (int n = 0; n < canvas_.taxels(); ++n)
      for (int a = 0; a < A_; ++a)
        canvas_values_[std::size_t(canvas_.pixel[std::size_t(n)]) * std::size_t(A_) + std::size_t(a)] =
            frame[std::size_t(n) * stride + std::size_t(a) * axis_stride];
    const float r = float(c_.range);
    const bool crop = rng && rng->uniform() < c_.crop_probability;
    if (!crop) {
      resample_image(out, canvas_values_.data(), W, A_, full_y_, full_x_, tmp_);
      scale(out, r);
    } else {
      full_.resize(image_values());
      resample_image(full_.data(), canvas_values_.data(), W, A_, full_y_, full_x_, tmp_);
      scale(full_.data(), r);
      const CropBox b = random_resized_crop(*rng, S, S, c_.crop_scale, c_.crop_ratio);
      resample_image(out, full_.data(), S, A_, ResampleAxis(b.top, b.height, S, S), ResampleAxis(b.left, b.width, S, S),
                     tmp_);
    }
    if (rng && rng->uniform() < c_.blur_probability)
      gaussian_blur3(out, S, S, A_, rng->uniform(c_.blur_sigma[0], c_.blur_sigma[1]), tmp_);
    for (std::size_t p = 0; p < std::size_t(S) * std::size_t(S); ++p)
      for (int a = 0; a < A_; ++a) {
        const double mean = c_.mean[c_.mean.size() == 1 ? 0 : std::size_t(a)];
        const double sd = c_.std[c_.std.size() == 1 ? 0 : std::size_t(a)];
        float& v = out[p * std::size_t(A_) + std::size_t(a)];
        v = float((v - mean) / sd);
      }
  }

 private:
  void scale(float* img, float r) const {
    for (std::size_t i = 0; i < image_values(); ++i) img[i] = (std::clamp(img[i], -r, r) + r) / (2 * r);
  }

  TaxelCanvas canvas_;
  int A_;
  TaxelImageConfig c_;
  ResampleAxis full_y_, full_x_;
  std::vector<float> canvas_values_, full_, tmp_;
};

}  // namespace tjepa
