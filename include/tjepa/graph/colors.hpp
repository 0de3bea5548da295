#pragma once
// Colours for drawings: a categorical palette (parts, groups) and the viridis colormap (per-taxel
// values), as CSS "#rrggbb" strings.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>

namespace tjepa {

// Colour k of a 20-colour categorical palette (Tableau 20 order: dark shades first), cycling.
inline std::string category_color(int k) {
  static constexpr std::array<const char*, 20> kPalette = {
      "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
      "#7f7f7f", "#bcbd22", "#17becf", "#aec7e8", "#ffbb78", "#98df8a", "#ff9896",
      "#c5b0d5", "#c49c94", "#f7b6d2", "#c7c7c7", "#dbdb8d", "#9edae5"};
  const int n = static_cast<int>(kPalette.size());
  return kPalette[((k % n) + n) % n];
}

// Viridis at t in [0, 1] (clamped; NaN gives light grey), linear between 9 control points.
inline std::string viridis(double t) {
  if (std::isnan(t)) return "#dddddd";
  static constexpr double kStops[9][3] = {
      {68, 1, 84},    {71, 44, 122},  {59, 81, 139},   {44, 113, 142}, {33, 144, 141},
      {39, 173, 129}, {92, 200, 99},  {170, 220, 50},  {253, 231, 37}};
  t = std::clamp(t, 0.0, 1.0) * 8.0;
  const int k = std::min(static_cast<int>(t), 7);
  const double f = t - k;
  char buf[8];
  int c[3];
  for (int a = 0; a < 3; ++a) c[a] = static_cast<int>(std::lround(kStops[k][a] + f * (kStops[k + 1][a] - kStops[k][a])));
  std::snprintf(buf, sizeof buf, "#%02x%02x%02x", c[0], c[1], c[2]);
  return buf;
}

}  // namespace tjepa
