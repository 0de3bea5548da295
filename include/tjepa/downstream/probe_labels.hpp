#pragma once
// The labels of a labelled WindowSource's windows (data/labels.hpp: per frame a 3-axis force
// and an indenter class) as targets of a ProbeHead (downstream/probe_head.hpp): R = 3 force
// axes, C = the indenter classes, trained early-stopped by train_head.
#include <cstdint>
#include <span>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/data/window_source.hpp"
#include "tjepa/downstream/probe_head.hpp"

namespace tjepa {

inline constexpr int force_axes = 3;

// The labels of S windows.
struct ProbeLabels {
  std::vector<std::int64_t> window;  // [S] window ids in their WindowSource
  std::vector<float> force;          // [S, 3] N (shear u, shear v, normal)
  std::vector<int> indenter;         // [S] class in [0, num_classes)

  int size() const { return static_cast<int>(indenter.size()); }

  // The labels of windows `ids` of a labelled source; every window must have a contact.
  static ProbeLabels from_source(const WindowSource& src, std::span<const std::int64_t> ids) {
    require<ConfigError>(src.has_labels(), "ProbeLabels::from_source: the windows have no labels");
    ProbeLabels l;
    for (std::int64_t id : ids) {
      const WindowLabel w = src.label(id);
      require<DataError>(w.indenter >= 0, "ProbeLabels::from_source: window ", id,
                         " has no contact, expected windows with an indenter class");
      l.window.push_back(id);
      l.force.insert(l.force.end(), w.force.begin(), w.force.end());
      l.indenter.push_back(w.indenter);
    }
    return l;
  }
};

// The same labels as targets of a general ProbeHead (downstream/probe_head.hpp), trained with
// early stopping by train_head: R = 3 force axes, C = num_classes indenter classes.
inline HeadTargets head_targets(const ProbeLabels& l, int num_classes) {
  HeadTargets t{force_axes, num_classes, l.force, l.indenter, {}};
  t.validate("head_targets");
  return t;
}

}  // namespace tjepa
