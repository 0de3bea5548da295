#pragma once
// Built-in layout: Xela uSkin on the Allegro hand (Sparsh-skin, paper Sec. IV-A), its pads and
// edges as in the reference implementation (E-Kovtun/tactile, tactile_ssl/graph/builders.py).
//
// 368 taxels in 18 pads, one part. Taxel order (the data's order): thumb tip, thumb pads 1-2; index,
// middle, ring (tip, then pads 1-3, tip-to-base); then palm pads 0-2. Inside a pad, live cells
// row-major from row 0. Pads:
//   fingertip  6 x 6 grid, rows 0-3 full, row 4 cols 1-4, row 5 cols 2-3 (30 taxels; rows 4-5 are
//              the curved tip), about 31 x 39 mm
//   phalanx    4 x 4, 4.667 mm pitch (26 x 24 mm pad)
//   palm       4 x 6, about 52 x 32 mm
// Edges: 4-neighbour grid edges inside each pad (570), and k = 4 bridges between each of the 17
// adjacent pad pairs (consecutive pads along a finger, each finger's base pad and the palm, palm
// pads to each other): 638 edges, one component. Weights: Euclidean distance in mm.
//
// Coordinates (mm, x right, y up) come from an invented flat drawing of the hand, not a CAD model:
// index, middle and ring as columns 34 mm apart above the palm (row 5 of a fingertip points away
// from the palm), the palm as three pads side by side (index over palm 0), the thumb tilted 35° to
// the left of palm 0. Only the adjacency is exact; the distances are plausible.
#include <array>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "tjepa/graph/skin.hpp"
#include "tjepa/sensors/layout_builder.hpp"

namespace tjepa::layouts {

namespace allegro {
inline constexpr int kTaxels = 368;
inline constexpr int kPads = 18;
inline constexpr int kIntraPadEdges = 570;
inline constexpr int kAdjacentPadPairs = 17;
inline constexpr int kBridgesPerPair = 4;
inline constexpr double kFingertipPitch = 31.0 / 6.0;  // mm along a row
inline constexpr double kFingertipRowPitch = 39.0 / 6.0;
inline constexpr double kPhalanxPitch = 4.667;
inline constexpr double kPalmPitch = 52.0 / 6.0;
inline constexpr double kPalmRowPitch = 32.0 / 4.0;

// The 6 x 6 fingertip grid with its 30 live cells.
inline GridPad fingertip_pad() {
  GridPad p(6, 6, kFingertipPitch, kFingertipRowPitch);
  p.live.assign(36, 0);
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c)
      p.live[r * 6 + c] = r < 4 || (r == 4 && c >= 1 && c <= 4) || (r == 5 && c >= 2 && c <= 3);
  return p;
}
inline GridPad phalanx_pad() { return GridPad(4, 4, kPhalanxPitch); }
inline GridPad palm_pad() { return GridPad(4, 6, kPalmPitch, kPalmRowPitch); }

// Pad names in taxel order (group id = position).
inline std::vector<std::string> pad_names() {
  return {"thumb_tip", "thumb_1",  "thumb_2",  "index_tip", "index_1", "index_2",
          "index_3",   "middle_tip", "middle_1", "middle_2", "middle_3", "ring_tip",
          "ring_1",    "ring_2",   "ring_3",   "palm_0",    "palm_1",  "palm_2"};
}

// The 17 physically adjacent pad pairs, by group id.
inline std::vector<GroupPair> adjacent_pads() {
  return {{0, 1},  {1, 2},  {2, 15},                    // thumb: tip-1-2, base to palm 0
          {3, 4},  {4, 5},  {5, 6},  {6, 15},           // index over palm 0
          {7, 8},  {8, 9},  {9, 10}, {10, 16},          // middle over palm 1
          {11, 12}, {12, 13}, {13, 14}, {14, 17},       // ring over palm 2
          {15, 16}, {16, 17}};                          // palm pads side by side
}
}  // namespace allegro

inline Skin allegro_xela() {
  using namespace allegro;
  LayoutBuilder b(2);
  const int hand = b.add_part("hand");
  const auto names = pad_names();
  int g = 0;
  // Pads along a finger, tip first, centred on x, from the tip's centre downwards.
  constexpr double kPadStep = 26.0;                    // phalanx pad centre-to-centre
  constexpr double kTipToPad = 19.5 + 2.0 + 12.0;      // half tip + gap + half pad
  auto finger = [&](double x0, double y_base, double angle_deg, int n_pads) {
    const double th = angle_deg * std::numbers::pi / 180.0;
    const double dx = -std::sin(th), dy = std::cos(th);  // unit vector towards the tip
    const double to_tip = (n_pads - 1) * kPadStep + kTipToPad;
    b.add_grid_pad(names[g++], hand, fingertip_pad(), {x0 + to_tip * dx, y_base + to_tip * dy, angle_deg});
    for (int k = n_pads - 1; k >= 0; --k)
      b.add_grid_pad(names[g++], hand, phalanx_pad(), {x0 + k * kPadStep * dx, y_base + k * kPadStep * dy, angle_deg});
  };
  finger(-30.0, -8.0, 35.0, 2);  // thumb, its base pad left of palm 0
  finger(0.0, 40.0, 0.0, 3);     // index
  finger(34.0, 40.0, 0.0, 3);    // middle
  finger(68.0, 40.0, 0.0, 3);    // ring
  // Palm pads stand upright (rows along -x, columns along +y): 32 mm wide, 52 mm tall.
  for (int k = 0; k < 3; ++k) b.add_grid_pad(names[g++], hand, palm_pad(), {34.0 * k, 0.0, 90.0});
  b.add_bridges(adjacent_pads(), kBridgesPerPair);
  return b.build();
}

}  // namespace tjepa::layouts
