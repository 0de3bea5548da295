// The simulated grasping hand (sim/grasping_hand.hpp, docs/grasping_hand.md): determinism, labels
// against the rendered signal, physical bounds of the forces, the pose, coverage of objects and
// grasps, config errors, and the magnetic preprocessing on its data. Also the contact model's
// generalized lobe patterns (sim/contact_model.hpp).
#include <doctest/doctest.h>

#include <tjepa/data/preprocessor.hpp>
#include <tjepa/sensors/allegro_xela.hpp>
#include <tjepa/sensors/generic.hpp>
#include <tjepa/sim/grasping_hand.hpp>
#include <tjepa/sim/simulated_skin.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <map>
#include <set>
#include <vector>

namespace {

const tjepa::TaxelLayout& hand_layout() {
  static const tjepa::Skin skin = tjepa::layouts::allegro_xela();
  return skin.layout;
}

tjepa::GraspSimConfig clean_config() {
  tjepa::GraspSimConfig c;
  c.noise_std = 0.0;
  c.drift_std = 0.0;
  c.dropout_rate = 0.0;
  return c;
}

// One frame, recorded on its own so the contacts rendered in it can be read.
struct Frame {
  std::vector<float> values;  // [N, 3] counts
  tjepa::GraspLabel label;
  std::vector<tjepa::SimulatedHand::Contact> contacts;
};

std::vector<Frame> record_frames(tjepa::SimulatedHand& sim, int frames) {
  std::vector<Frame> out(static_cast<std::size_t>(frames));
  for (Frame& f : out) {
    const tjepa::GraspRecording r = sim.record(1);
    f.values.assign(r.recording.values().begin(), r.recording.values().end());
    f.label = r.labels[0];
    f.contacts = sim.contacts();
  }
  return out;
}

bool same_label(const tjepa::GraspLabel& a, const tjepa::GraspLabel& b) {
  return a.episode == b.episode && a.episode_object == b.episode_object && a.object == b.object && a.grasp == b.grasp && a.phase == b.phase && a.held == b.held && a.x_cm == b.x_cm &&
         a.y_cm == b.y_cm && a.theta_deg == b.theta_deg && a.force == b.force && a.contact_mask == b.contact_mask;
}

// Sum over pad p's taxels of the z reading minus the offset (counts).
double pad_z_signal(const tjepa::SimulatedHand& sim, const float* f, int p) {
  double s = 0;
  for (int i : sim.pads()[p].taxels) s += f[3 * i + 2] - sim.offsets()[3 * static_cast<std::size_t>(i) + 2];
  return s;
}

}  // namespace

TEST_SUITE("sim") {
  TEST_CASE("grasping hand: the same seed gives the same recording and labels / another seed does not") {
    tjepa::SimulatedHand a(hand_layout(), {}, 7), b(hand_layout(), {}, 7), c(hand_layout(), {}, 8);
    const tjepa::Recording base_a = a.record_baseline(50), base_b = b.record_baseline(50);
    CHECK(std::equal(base_a.values().begin(), base_a.values().end(), base_b.values().begin()));
    const tjepa::GraspRecording ra = a.record(3000), rb = b.record(3000), rc = c.record(3000);
    CHECK(ra.recording.frames() == 3000);
    CHECK(ra.recording.taxels() == 368);
    CHECK(ra.recording.axes() == 3);
    CHECK(std::equal(ra.recording.values().begin(), ra.recording.values().end(), rb.recording.values().begin()));
    bool labels_equal = true;
    for (std::size_t t = 0; t < ra.labels.size(); ++t) labels_equal = labels_equal && same_label(ra.labels[t], rb.labels[t]);
    CHECK(labels_equal);
    CHECK_FALSE(std::equal(ra.recording.values().begin(), ra.recording.values().end(), rc.recording.values().begin()));
    bool labels_differ = false;
    for (std::size_t t = 0; t < ra.labels.size(); ++t) labels_differ = labels_differ || !same_label(ra.labels[t], rc.labels[t]);
    CHECK(labels_differ);
    // Recording in pieces continues the same episodes: 1000 + 2000 frames equal 3000.
    tjepa::SimulatedHand d(hand_layout(), {}, 7);
    d.record_baseline(50);
    const tjepa::GraspRecording d1 = d.record(1000), d2 = d.record(2000);
    CHECK(std::equal(d1.recording.values().begin(), d1.recording.values().end(), ra.recording.values().begin()));
    CHECK(std::equal(d2.recording.values().begin(), d2.recording.values().end(),
                     ra.recording.values().begin() + static_cast<std::ptrdiff_t>(d1.recording.size())));
    // reseed: new episodes on the same sensor, deterministic.
    tjepa::SimulatedHand e(hand_layout(), {}, 7), f(hand_layout(), {}, 7);
    e.reseed(3);
    f.reseed(3);
    CHECK(e.offsets() == a.offsets());
    const tjepa::GraspRecording re = e.record(500), rf = f.record(500);
    CHECK(std::equal(re.recording.values().begin(), re.recording.values().end(), rf.recording.values().begin()));
  }

  TEST_CASE("grasping hand: a pad in contact carries signal and a free pad reads its offset exactly") {
    tjepa::SimulatedHand sim(hand_layout(), clean_config(), 2);
    const std::vector<Frame> frames = record_frames(sim, 6000);
    int contact_frames = 0;
    double weakest = 1e300;
    for (const Frame& f : frames) {
      std::uint32_t mask = 0;
      for (const auto& c : f.contacts) mask |= 1u << c.state.pad;
      REQUIRE(mask == f.label.contact_mask);
      for (int p = 0; p < 18; ++p) {
        if (mask >> p & 1u) {
          // Noise-free, any contact shows; the weakest are 0.05 N (the threshold) lines lying
          // between the rows of a sparse pad (palm: 8 mm pitch), a few counts.
          weakest = std::min(weakest, pad_z_signal(sim, f.values.data(), p));
          continue;
        }
        bool at_offset = true;
        for (int i : sim.pads()[p].taxels)
          for (int a = 0; a < 3; ++a)
            at_offset = at_offset && f.values[3 * static_cast<std::size_t>(i) + a] == sim.offsets()[3 * static_cast<std::size_t>(i) + a];
        CHECK(at_offset);
      }
      contact_frames += mask != 0;
    }
    CHECK(contact_frames > 3000);
    CHECK(weakest > 1.0);
  }

  TEST_CASE("grasping hand: with sensor noise a firm contact stands well above the noise of its pad") {
    tjepa::GraspSimConfig cfg = clean_config();
    cfg.noise_std = 10.0;
    tjepa::SimulatedHand sim(hand_layout(), cfg, 4);
    const std::vector<Frame> frames = record_frames(sim, 4000);
    int firm = 0;
    for (const Frame& f : frames) {
      for (const auto& c : f.contacts) {
        const int n = static_cast<int>(sim.pads()[c.state.pad].taxels.size());
        const double noise = cfg.noise_std * std::sqrt(static_cast<double>(n));  // std of the pad's sum
        // From 1 N up even a line between a palm pad's taxel rows sums above 5 σ of the pad's noise.
        if (c.state.normal >= 1.0) {
          ++firm;
          CHECK(pad_z_signal(sim, f.values.data(), c.state.pad) > 5.0 * noise);
        }
      }
      for (int p = 0; p < 18; ++p)
        if (!(f.label.contact_mask >> p & 1u)) CHECK(std::abs(pad_z_signal(sim, f.values.data(), p)) < 5.0 * 10.0 * std::sqrt(30.0));
    }
    CHECK(firm > 500);
  }

  TEST_CASE("grasping hand: forces stay within friction and the grip holds the weight") {
    tjepa::SimulatedHand sim(hand_layout(), clean_config(), 5);
    const std::vector<Frame> frames = record_frames(sim, 15000);
    const double g = sim.config().gravity;
    int held = 0;
    double peak = 0;
    for (const Frame& f : frames) {
      double capacity = 0;
      for (const auto& c : f.contacts) {
        const tjepa::ContactState& s = c.state;
        CHECK(s.normal >= sim.config().contact_threshold);
        CHECK(std::hypot(s.shear_u, s.shear_v) <= c.friction * s.normal * (1 + 1e-9) + 1e-12);
        peak = std::max(peak, s.normal);
        capacity += c.friction * s.normal;
        if (s.pad == sim.config().label_pad) {
          CHECK(f.label.force[2] == static_cast<float>(s.normal));
          CHECK(f.label.force[0] == static_cast<float>(s.shear_u));
        }
      }
      if (!(f.label.contact_mask >> sim.config().label_pad & 1u)) CHECK(f.label.force == std::array<float, 3>{});
      if (f.label.held) {
        ++held;
        const tjepa::GraspObject& o = tjepa::grasp_objects()[static_cast<std::size_t>(f.label.object)];
        CHECK(capacity >= o.weight(g));
        CHECK(f.contacts.size() >= 2);
      }
    }
    CHECK(held > 5000);
    // The heaviest grip: the 0.5 kg bottle at the largest safety margin, 2.2 · 4.9 N / 0.6 = 18 N
    // over at least 13 contacts.
    CHECK(peak > 0.5);
    CHECK(peak < 15.0);
  }

  TEST_CASE("grasping hand: the pose changes only while held and moves the contacts") {
    tjepa::SimulatedHand sim(hand_layout(), clean_config(), 6);
    const std::vector<Frame> frames = record_frames(sim, 15000);
    const auto& cfg = sim.config();
    int moved = 0, rotated = 0, still_checked = 0;
    std::set<int> phases;
    for (std::size_t t = 0; t < frames.size(); ++t) {
      const tjepa::GraspLabel& l = frames[t].label;
      phases.insert(l.phase);
      CHECK(std::abs(l.x_cm) <= cfg.max_offset_cm);
      CHECK(std::abs(l.y_cm) <= cfg.max_offset_cm);
      CHECK(std::abs(l.theta_deg) <= cfg.max_theta_deg);
      if (l.object < 0) {
        CHECK(l.x_cm == 0.0f);
        CHECK(l.theta_deg == 0.0f);
        CHECK_FALSE(l.held);
        CHECK(std::popcount(l.contact_mask) <= 1);  // at most an incidental touch
      }
      if (t == 0) continue;
      const tjepa::GraspLabel& p = frames[t - 1].label;
      if (p.object != l.object) continue;
      const bool pose_changed = p.x_cm != l.x_cm || p.y_cm != l.y_cm || p.theta_deg != l.theta_deg;
      if (pose_changed) CHECK(l.held);
      if (!pose_changed || l.phase == static_cast<int>(tjepa::GraspPhase::regrasp)) continue;
      ++moved;
      rotated += p.theta_deg != l.theta_deg;
      // A pose change moves the contacts that stay on (the same pads in both frames).
      bool any_moved = false;
      for (const auto& c : frames[t].contacts)
        for (const auto& d : frames[t - 1].contacts)
          if (c.state.pad == d.state.pad)
            any_moved = any_moved || c.state.u != d.state.u || c.state.v != d.state.v ||
                        c.state.orientation != d.state.orientation;
      CHECK(any_moved);
    }
    // While holding still, the contacts do not move.
    for (std::size_t t = 1; t < frames.size(); ++t) {
      if (frames[t].label.phase != static_cast<int>(tjepa::GraspPhase::hold) ||
          frames[t - 1].label.phase != static_cast<int>(tjepa::GraspPhase::hold))
        continue;
      REQUIRE(frames[t].contacts.size() == frames[t - 1].contacts.size());
      for (std::size_t k = 0; k < frames[t].contacts.size(); ++k) {
        CHECK(frames[t].contacts[k].state.u == frames[t - 1].contacts[k].state.u);
        CHECK(frames[t].contacts[k].state.v == frames[t - 1].contacts[k].state.v);
        ++still_checked;
      }
    }
    CHECK(moved > 1000);
    CHECK(rotated > 300);
    CHECK(still_checked > 1000);
    CHECK(phases.size() == static_cast<std::size_t>(tjepa::num_grasp_phases));
  }

  TEST_CASE("grasping hand: every object and grasp appears and grasps touch several pads at once") {
    tjepa::SimulatedHand sim(hand_layout(), {}, 9);
    const tjepa::GraspRecording r = sim.record(20000);
    CHECK(tjepa::num_grasp_objects() >= 14);
    std::set<int> objects, grasps, pads;
    int multi = 0, held = 0, power_wide = 0, mask_changes = 0;
    for (std::size_t t = 0; t < r.labels.size(); ++t) {
      const tjepa::GraspLabel& l = r.labels[t];
      if (l.object >= 0) objects.insert(l.object);
      if (l.grasp >= 0) grasps.insert(l.grasp);
      for (int p = 0; p < 18; ++p)
        if (l.contact_mask >> p & 1u) pads.insert(p);
      CHECK(l.contact_mask < (1u << 18));
      if (l.held) {
        ++held;
        multi += std::popcount(l.contact_mask) >= 3;
        power_wide += l.grasp == static_cast<int>(tjepa::GraspType::power) && std::popcount(l.contact_mask) >= 10;
      }
      if (t > 0 && l.object >= 0 && l.object == r.labels[t - 1].object) mask_changes += l.contact_mask != r.labels[t - 1].contact_mask;
    }
    CHECK(objects.size() == static_cast<std::size_t>(tjepa::num_grasp_objects()));
    CHECK(grasps.size() == static_cast<std::size_t>(tjepa::num_grasp_types));
    CHECK(pads.size() == 18);
    CHECK(multi > held / 3);
    CHECK(power_wide > 500);
    CHECK(mask_changes > 200);  // contacts come on and off within episodes, not all at once
    // Every object's grasps are ones it allows, and its numbers are physical.
    for (const tjepa::GraspObject& o : tjepa::grasp_objects()) {
      CAPTURE(o.name);
      CHECK(o.grasps != 0u);
      CHECK(o.mass > 0);
      CHECK(o.friction > 0);
      CHECK(o.contact_size > 0);
    }
    for (const tjepa::GraspLabel& l : r.labels)
      if (l.object >= 0) CHECK(tjepa::grasp_objects()[static_cast<std::size_t>(l.object)].allows(static_cast<tjepa::GraspType>(l.grasp)));
  }

  TEST_CASE("grasping hand: episodes count up - hold one object each - and stay unique across reseed") {
    tjepa::SimulatedHand sim(hand_layout(), {}, 4);
    const tjepa::GraspRecording a = sim.record(6000);
    sim.reseed(5);
    const tjepa::GraspRecording b = sim.record(3000);
    std::map<int, int> object_of;
    int last = -1;
    for (const tjepa::GraspRecording* r : {&a, &b})
      for (const tjepa::GraspLabel& l : r->labels) {
        REQUIRE(l.episode >= 0);
        CHECK((l.episode == last || l.episode == last + 1));  // counts up by one, never back
        last = l.episode;
        CHECK(l.episode_object >= 0);
        if (l.object >= 0) CHECK(l.object == l.episode_object);
        const auto [at, fresh] = object_of.emplace(l.episode, l.episode_object);
        CHECK(at->second == l.episode_object);  // one object per episode
      }
    CHECK(object_of.size() > 12u);  // about 5 s per episode
    CHECK(a.labels.back().episode < b.labels.front().episode);  // reseed starts a new episode, new id
    CHECK(a.labels.front().episode == 0);
  }

  TEST_CASE("grasping hand: bad config and layout errors name the field") {
    auto fails_with = [](const tjepa::GraspSimConfig& c, const char* text) {
      CHECK_THROWS_WITH_AS(tjepa::SimulatedHand(hand_layout(), c, 0), doctest::Contains(text), tjepa::ConfigError);
    };
    tjepa::GraspSimConfig c;
    c.label_pad = 18;
    fails_with(c, "label_pad = 18");
    c = {};
    c.safety_min = 0.8;
    fails_with(c, "safety range [0.8, 2.2]");
    c = {};
    c.rotate_frames_min = 50;
    c.rotate_frames_max = 10;
    fails_with(c, "rotate_frames range [50, 10]");
    c = {};
    c.noise_std = -1;
    fails_with(c, "GraspSimConfig: noise_std = -1");
    c = {};
    c.start_theta_deg = 40;
    fails_with(c, "start_theta_deg = 40");
    c = {};
    c.touch_probability = 1.5;
    fails_with(c, "touch_probability = 1.5");
    CHECK_THROWS_WITH_AS(tjepa::SimulatedHand(tjepa::layouts::grid_skin().layout, {}, 0),
                         doctest::Contains("expected the Allegro/Xela layout"), tjepa::ConfigError);
    tjepa::SimulatedHand sim(hand_layout(), {}, 0);
    CHECK_THROWS_WITH_AS(sim.record(-1), doctest::Contains("frames = -1"), tjepa::ConfigError);
    CHECK_THROWS_AS(sim.record_baseline(-2), tjepa::ConfigError);
  }

  TEST_CASE("grasping hand: the magnetic preprocessing takes its data with a baseline") {
    tjepa::SimulatedHand sim(hand_layout(), {}, 11);
    tjepa::Preprocessor pre(tjepa::PreprocessConfig::xela_counts());
    pre.fit_baseline(sim.record_baseline(500));
    const tjepa::GraspRecording r = sim.record(4000);
    pre.fit(r.recording);
    REQUIRE(pre.ready());
    for (int i = 0; i < sim.taxels(); ++i)
      CHECK(pre.baseline()[3 * static_cast<std::size_t>(i) + 2] ==
            doctest::Approx(sim.offsets()[3 * static_cast<std::size_t>(i) + 2]).epsilon(0.01));
    const tjepa::Recording x = pre.transformed(r.recording);
    bool finite = true;
    for (float v : x.values()) finite = finite && std::isfinite(v);
    CHECK(finite);
    // Standardized z on the label pad: larger in contact than free (free taxels carry the drift,
    // 30 counts, against a per-axis std of a few tens of counts).
    const int p = sim.config().label_pad;
    double on = 0, off = 0;
    int n_on = 0, n_off = 0;
    for (int t = 0; t < x.frames(); ++t) {
      double s = 0;
      for (int i : sim.pads()[p].taxels) s += std::abs(x(t, i, 2));
      if (r.labels[static_cast<std::size_t>(t)].force[2] > 0.3f) {
        on += s;
        ++n_on;
      } else if (r.labels[static_cast<std::size_t>(t)].contact_mask == 0) {
        off += s;
        ++n_off;
      }
    }
    REQUIRE(n_on > 100);
    REQUIRE(n_off > 100);
    CHECK(on / n_on > 1.3 * off / n_off);
  }

  TEST_CASE("contact model: ring-like multi-point patterns and wide ridges") {
    const tjepa::SimulatedSkin sim(hand_layout(), tjepa::SimConfig{}, 1);
    std::vector<float> a(static_cast<std::size_t>(sim.taxels()) * 3), b(a.size());
    auto footprint = [&](const std::vector<float>& out, int pad) {
      int n = 0;
      double total = 0;
      for (int i : sim.pad_taxels(pad)) {
        n += out[3 * static_cast<std::size_t>(i) + 2] > 1.0f;
        total += out[3 * static_cast<std::size_t>(i) + 2];
      }
      return std::pair<int, double>{n, total};
    };
    tjepa::ContactState c;
    c.pad = 3;
    c.normal = 2.0;
    c.shape = tjepa::IndenterShape::multi_point;
    c.size = 8.0;
    c.points = 12;
    sim.respond(c, a);
    c.points = 3;
    sim.respond(c, b);
    CHECK(a != b);
    // The same force either way: the totals agree to within what the taxel grid samples.
    CHECK(footprint(a, 3).second == doctest::Approx(footprint(b, 3).second).epsilon(0.35));
    c.shape = tjepa::IndenterShape::edge;
    c.size = 10.0;
    c.edge_radius = 1.0;
    sim.respond(c, a);
    c.edge_radius = 35.0;  // a bottle: a line contact several mm wide
    sim.respond(c, b);
    CHECK(footprint(b, 3).first >= footprint(a, 3).first);
    double peak_a = 0, peak_b = 0;
    for (int i : sim.pad_taxels(3)) {
      peak_a = std::max(peak_a, static_cast<double>(a[3 * static_cast<std::size_t>(i) + 2]));
      peak_b = std::max(peak_b, static_cast<double>(b[3 * static_cast<std::size_t>(i) + 2]));
    }
    CHECK(peak_b < peak_a);  // the same force spread wider
  }
}
