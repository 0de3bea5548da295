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
// Edges: 4-neighbour grid edges inside each pad (570), and k = 4 bridges between each of the
// reference's 17 pad pairs (adjacent_pads()): 638 edges, one component. Weights: Euclidean
// distance in mm.
//
// Coordinates (mm, x right, y up) come from an invented flat drawing of the hand, not a CAD model:
// index, middle and ring as columns 34 mm apart above the palm (row 5 of a fingertip points away
// from the palm), the palm as three pads side by side in the reference's chain (palm 1, palm 0
// under index and middle, palm 2 under the ring), the thumb tilted 35° to the left of palm 1. The
// reference rebuilds its bridges per window from the hand's 3-D pose; here they are fixed. Only the
// adjacency is the reference's; the distances are plausible.
//
// Recordings from XELA's driver or the reference code come in other taxel orders: xserver_columns()
// and reference_columns() (`--order xserver|reference`).
#include <array>
#include <cmath>
#include <iterator>
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

// The 17 bridged pad pairs, by group id, as the reference's graph builder lists them
// (tactile_ssl/graph/utils.py, PHYSICAL_BRIDGE_LINK_PAIRS): along each finger, each finger's base
// pad to a palm pad (thumb to palm_1, index and middle to palm_0, ring to palm_2), and the palm
// chained palm_1 - palm_0 - palm_2. A later revision of that file joins the ring to palm_1 instead.
inline std::vector<GroupPair> adjacent_pads() {
  return {{0, 1},  {1, 2},  {2, 16},                    // thumb: tip-1-2, base to palm 1
          {3, 4},  {4, 5},  {5, 6},  {6, 15},           // index over palm 0
          {7, 8},  {8, 9},  {9, 10}, {10, 15},          // middle over palm 0
          {11, 12}, {12, 13}, {13, 14}, {14, 17},       // ring over palm 2
          {15, 16}, {15, 17}};                          // palm 1 - palm 0 - palm 2
}

// The orders in which recordings arrive, as TaxelLayout::column (entry j: the recording's column
// of taxel j). tjepa's order is the reference's pad order with each pad row-major from row 0.
//
// xServer (XELA's driver; the `point_id` 0-367 of its messages on the curved-tip Allegro hand):
// XELA numbers the sensors thumb tip, thumb 1, 2; index, middle, ring (tip, then the phalanx pads
// from the tip); palm 1, 2, 3 (= palm_0, palm_1, palm_2), and each sensor's taxels row-major in
// its own numbering, which is the reference's: a fingertip from its 2-cell dome row (tjepa row 5)
// down, columns as tjepa's; phalanx and palm pads as tjepa's. The point_ids of those taxels are
// interleaved: XELA's canvas is scanned column by column across the hand.
// Source: the index arrays of NYU-robot-learning/Xela-Sensor-Controllers-Openteach,
// xela_sensors/src/xela_sensors/utils.py (index fingertip row 0 read as [-1, -1, 101, 83, -1, -1],
// as its columns continue), checked against them in tests/graph/real_skins.cpp.
inline std::vector<int> xserver_columns() {
  static constexpr int point_id[kTaxels] = {
      // thumb_tip
      61, 49, 36, 22, 8, 3, 60, 48, 35, 21, 7, 2, 59, 47, 34, 20, 6, 1, 58, 46, 33, 19, 5, 0, 45, 32,
      18, 4, 31, 17,
      // thumb_1
      50, 37, 23, 9, 51, 38, 24, 10, 52, 39, 25, 11, 53, 40, 26, 12,
      // thumb_2
      54, 41, 27, 13, 55, 42, 28, 14, 56, 43, 29, 15, 57, 44, 30, 16,
      // index_tip
      147, 127, 106, 88, 70, 65, 146, 126, 105, 87, 69, 64, 145, 125, 104, 86, 68, 63, 144, 124, 103,
      85, 67, 62, 123, 102, 84, 66, 101, 83,
      // index_1
      128, 107, 89, 71, 129, 108, 90, 72, 130, 109, 91, 73, 131, 110, 92, 74,
      // index_2
      132, 111, 93, 75, 133, 112, 94, 76, 134, 113, 95, 77, 135, 114, 96, 78,
      // index_3
      136, 115, 97, 79, 137, 116, 98, 80, 138, 117, 99, 81, 139, 118, 100, 82,
      // middle_tip
      249, 225, 208, 190, 168, 159, 248, 224, 207, 189, 167, 158, 247, 223, 206, 188, 166, 157, 246,
      222, 205, 187, 165, 156, 221, 204, 186, 164, 203, 185,
      // middle_1
      226, 209, 191, 169, 227, 210, 192, 170, 228, 211, 193, 171, 229, 212, 194, 172,
      // middle_2
      230, 213, 195, 173, 231, 214, 196, 174, 232, 215, 197, 175, 233, 216, 198, 176,
      // middle_3
      234, 217, 199, 177, 235, 218, 200, 178, 236, 219, 201, 179, 237, 220, 202, 180,
      // ring_tip
      367, 351, 334, 308, 282, 269, 366, 350, 333, 307, 281, 268, 365, 349, 332, 306, 280, 267, 364,
      348, 331, 305, 279, 266, 347, 330, 304, 278, 329, 303,
      // ring_1
      352, 335, 309, 283, 353, 336, 310, 284, 354, 337, 311, 285, 355, 338, 312, 286,
      // ring_2
      356, 339, 313, 287, 357, 340, 314, 288, 358, 341, 315, 289, 359, 342, 316, 290,
      // ring_3
      360, 343, 317, 291, 361, 344, 318, 292, 362, 345, 319, 293, 363, 346, 320, 294,
      // palm_0
      119, 140, 148, 152, 160, 181, 120, 141, 149, 153, 161, 182, 121, 142, 150, 154, 162, 183, 122,
      143, 151, 155, 163, 184,
      // palm_1
      238, 250, 258, 270, 295, 321, 239, 251, 259, 271, 296, 322, 240, 252, 260, 272, 297, 323, 241,
      253, 261, 273, 298, 324,
      // palm_2
      242, 254, 262, 274, 299, 325, 243, 255, 263, 275, 300, 326, 244, 256, 264, 276, 301, 327, 245,
      257, 265, 277, 302, 328,
  };
  return std::vector<int>(std::begin(point_id), std::end(point_id));
}

// The Tactile-JEPA reference code's data order (E-Kovtun/tactile, its Xela data and atlas): tjepa's
// pad order, phalanx and palm pads as tjepa, fingertips with the rows the other way (the 2-cell dome
// row first, then the 4-cell row, then the full rows from the dome side; columns kept).
inline std::vector<int> reference_columns() {
  // Reference local index k of a fingertip -> tjepa local index.
  static constexpr int tip[30] = {28, 29, 24, 25, 26, 27, 18, 19, 20, 21, 22, 23, 12, 13, 14,
                                  15, 16, 17, 6,  7,  8,  9,  10, 11, 0,  1,  2,  3,  4,  5};
  std::vector<int> column(kTaxels);
  for (int j = 0; j < kTaxels; ++j) column[static_cast<std::size_t>(j)] = j;
  for (int first : {0, 62, 140, 218})  // the four fingertips' first taxels
    for (int k = 0; k < 30; ++k) column[static_cast<std::size_t>(first + tip[k])] = first + k;
  return column;
}

// The reference's taxel type of each token in its order (XELA_FLATTEN_ORDER of
// tactile_ssl/data/xela/utils.py): rows of taxeltype_embed 0 = 4x4 pad, 1 = 4x6 palm pad, 2 = curved
// fingertip. That order's pads are tjepa's, so this is also the type of each tjepa taxel.
inline std::vector<int> reference_taxel_types() {
  std::vector<int> t;
  const auto pad = [&](int n, int type) { t.insert(t.end(), static_cast<std::size_t>(n), type); };
  pad(30, 2), pad(32, 0);                 // thumb: tip, 2 pads
  for (int f = 0; f < 3; ++f) pad(30, 2), pad(48, 0);  // index, middle, ring: tip, 3 pads
  pad(72, 1);                             // three palm pads
  return t;
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
  finger(-48.0, -12.0, 35.0, 2);  // thumb, its base pad left of palm 1
  finger(0.0, 40.0, 0.0, 3);      // index
  finger(34.0, 40.0, 0.0, 3);     // middle
  finger(68.0, 40.0, 0.0, 3);     // ring
  // Palm pads stand upright (rows along -x, columns along +y): 32 mm wide, 52 mm tall, side by
  // side as the reference's pairs chain them: palm 1 (thumb side), palm 0 (under index and
  // middle), palm 2 (under the ring finger).
  for (const double x : {17.0, -17.0, 51.0}) b.add_grid_pad(names[g++], hand, palm_pad(), {x, 0.0, 90.0});
  b.add_bridges(adjacent_pads(), kBridgesPerPair);
  return b.build();
}

}  // namespace tjepa::layouts
