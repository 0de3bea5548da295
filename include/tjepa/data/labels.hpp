#pragma once
// Ground-truth labels for downstream probes: per frame (what the simulated skin knows), and per
// window (what a probe regresses or classifies).
#include <array>
#include <span>

namespace tjepa {

// The contact during one frame. Without contact: zero force, indenter = pad = -1.
struct FrameLabel {
  std::array<float, 3> force{};     // N, in the contacted pad's frame: (shear u, shear v, normal)
  std::array<float, 3> location{};  // mm, layout coordinates of the contact centre
  int indenter = -1;                // indenter class (see IndenterShape), -1: no contact
  int pad = -1;                     // group (pad) in contact, -1: none
};

// The labels of one window of τ frames.
struct WindowLabel {
  std::array<float, 3> force{};     // mean over the τ frames (free frames count as zero force)
  std::array<float, 3> location{};  // at the frame of largest normal force
  int indenter = -1;                // of that frame; -1 if no frame is in contact
  int pad = -1;
  int contact_frames = 0;           // frames of the window in contact, in [0, τ]
};

inline WindowLabel window_label(std::span<const FrameLabel> frames) {
  WindowLabel w;
  float best = -1.0f;
  for (const FrameLabel& f : frames) {
    for (int k = 0; k < 3; ++k) w.force[k] += f.force[k];
    if (f.indenter < 0) continue;
    ++w.contact_frames;
    if (f.force[2] > best) {
      best = f.force[2];
      w.location = f.location;
      w.indenter = f.indenter;
      w.pad = f.pad;
    }
  }
  if (!frames.empty())
    for (float& v : w.force) v /= static_cast<float>(frames.size());
  return w;
}

}  // namespace tjepa
