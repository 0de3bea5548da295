// The simulated skin's physics and labels, the drift tracker (data/drift_tracker.hpp), the
// preprocessor, windowing, batches and the grouped gather, and the grouped gather feeding the
// grouped tokenizer.
#include <doctest/doctest.h>

#include <tjepa/data/drift_tracker.hpp>
#include <tjepa/eval.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <set>
#include <vector>

namespace {

// Three pads: a flat 6×6 grid (pitch 3 mm), a flat 4×6 grid, and a curved 5×6 "fingertip".
tjepa::SkinGeometry test_geometry() {
  tjepa::SkinGeometry g;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) {
      g.position.push_back({3.0 * c, 3.0 * r, 0.0});
      g.pad.push_back(0);
    }
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 6; ++c) {
      g.position.push_back({40.0 + 4.667 * c, 4.667 * r, 0.0});
      g.pad.push_back(1);
    }
  for (int r = 0; r < 5; ++r)
    for (int c = 0; c < 6; ++c) {
      const double x = 4.5 * (c - 2.5), y = 60.0 + 4.5 * r;
      g.position.push_back({x, y, 0.02 * x * x});
      g.pad.push_back(2);
    }
  return g;
}

tjepa::SimConfig quiet_config() {
  tjepa::SimConfig c;
  c.drift_std = 0.0;
  c.dropout_rate = 0.0;
  return c;
}

// z-signal-weighted centroid (layout mm) of pad p's taxels in frame f minus offsets.
std::array<double, 3> centroid(const tjepa::SimulatedSkin& sim, const float* f, int p) {
  std::array<double, 3> c{};
  double w = 0;
  for (int i : sim.pad_taxels(p)) {
    const double s = std::max(0.0, static_cast<double>(f[3 * i + 2] - sim.offsets()[3 * i + 2]));
    for (int a = 0; a < 3; ++a) c[a] += s * sim.geometry().position[i][a];
    w += s;
  }
  for (auto& v : c) v /= std::max(w, 1e-12);
  return c;
}

double corr(const std::vector<double>& a, const std::vector<double>& b) {
  const double n = static_cast<double>(a.size());
  const double ma = std::accumulate(a.begin(), a.end(), 0.0) / n, mb = std::accumulate(b.begin(), b.end(), 0.0) / n;
  double sab = 0, saa = 0, sbb = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    sab += (a[i] - ma) * (b[i] - mb);
    saa += (a[i] - ma) * (a[i] - ma);
    sbb += (b[i] - mb) * (b[i] - mb);
  }
  return sab / std::sqrt(saa * sbb);
}

}  // namespace

TEST_SUITE("data") {
  TEST_CASE("simulated skin: more normal force gives more response and nothing off the touched pad") {
    const tjepa::SimulatedSkin sim(test_geometry(), tjepa::SimConfig{}, 1);
    std::vector<float> out(static_cast<std::size_t>(sim.taxels()) * 3);
    for (int shape = 0; shape < tjepa::num_indenter_shapes; ++shape) {
      CAPTURE(tjepa::indenter_name(shape));
      double last_total = 0, last_peak = 0;
      for (double force : {0.25, 0.5, 1.0, 2.0, 4.0, 8.0}) {
        tjepa::ContactState c;
        c.shape = static_cast<tjepa::IndenterShape>(shape);
        c.size = 4.0;
        c.pad = 0;
        c.normal = force;
        sim.respond(c, out);
        double total = 0, peak = 0;
        for (int i : sim.pad_taxels(0)) {
          total += out[3 * i + 2];
          peak = std::max(peak, static_cast<double>(out[3 * i + 2]));
        }
        CHECK(total > last_total);
        CHECK(peak > last_peak);
        last_total = total;
        last_peak = peak;
        for (int p : {1, 2})
          for (int i : sim.pad_taxels(p))
            for (int a = 0; a < 3; ++a) CHECK(out[3 * i + a] == 0.0f);
      }
    }
  }

  TEST_CASE("simulated skin: the response moves with the indenter and shear follows the traction") {
    const tjepa::SimulatedSkin sim(test_geometry(), quiet_config(), 2);
    std::vector<float> out(static_cast<std::size_t>(sim.taxels()) * 3);
    std::vector<float> offsets_zero(out.size(), 0.0f);
    double last = -1e9;
    for (double u = -4.0; u <= 4.0; u += 1.0) {
      tjepa::ContactState c;
      c.pad = 0;
      c.u = u;
      c.v = 0.5;
      c.size = 5.0;
      c.normal = 2.0;
      sim.respond(c, out);
      // Centroid in the pad plane.
      double cu = 0, cv = 0, w = 0;
      for (int i : sim.pad_taxels(0)) {
        const double s = out[3 * i + 2];
        cu += s * sim.taxel_uv(i)[0];
        cv += s * sim.taxel_uv(i)[1];
        w += s;
      }
      cu /= w;
      cv /= w;
      CHECK(cu > last);
      CHECK(std::abs(cu - u) < 1.5);
      CHECK(std::abs(cv - 0.5) < 1.5);
      last = cu;
    }
    // Tangential force along +u gives positive x shear, and reversing it flips the sign.
    tjepa::ContactState c;
    c.pad = 0;
    c.normal = 2.0;
    c.shear_u = 1.0;
    sim.respond(c, out);
    double sx = 0, sy = 0;
    for (int i : sim.pad_taxels(0)) {
      sx += out[3 * i];
      sy += out[3 * i + 1];
    }
    CHECK(sx > 0);
    CHECK(std::abs(sy) < 0.05 * sx);
    c.shear_u = -1.0;
    sim.respond(c, out);
    double sx2 = 0;
    for (int i : sim.pad_taxels(0)) sx2 += out[3 * i];
    CHECK(sx2 == doctest::Approx(-sx).epsilon(0.02));
  }

  TEST_CASE("simulated skin: a flat punch keeps its contact area while a sphere's grows with force") {
    const tjepa::SimulatedSkin sim(test_geometry(), quiet_config(), 3);
    std::vector<float> lo(static_cast<std::size_t>(sim.taxels()) * 3), hi(lo.size());
    // Forces low enough that the soft saturation is negligible.
    auto ratios = [&](tjepa::IndenterShape shape, double f) {
      tjepa::ContactState c;
      c.shape = shape;
      c.size = 4.0;
      c.pad = 0;
      c.normal = f;
      sim.respond(c, lo);
      c.normal = 2 * f;
      sim.respond(c, hi);
      std::vector<double> r;
      for (int i : sim.pad_taxels(0))
        if (lo[3 * i + 2] > 1.0f) r.push_back(hi[3 * i + 2] / lo[3 * i + 2]);
      return r;
    };
    for (double r : ratios(tjepa::IndenterShape::flat, 0.2)) CHECK(r == doctest::Approx(2.0).epsilon(0.01));
    const auto s = ratios(tjepa::IndenterShape::sphere, 1.0);
    CHECK(*std::min_element(s.begin(), s.end()) < 1.9);  // the centre gains less ...
    CHECK(*std::max_element(s.begin(), s.end()) > 2.1);  // ... than the rim: the contact spreads
  }

  TEST_CASE("simulated skin: recordings are deterministic and labelled and quiet away from contact") {
    const auto geo = test_geometry();
    tjepa::SimulatedSkin a(geo, quiet_config(), 7), b(geo, quiet_config(), 7), c(geo, quiet_config(), 8);
    const auto ra = a.record(3000), rb = b.record(3000), rc = c.record(3000);
    REQUIRE(ra.recording.size() == rb.recording.size());
    CHECK(std::equal(ra.recording.values().begin(), ra.recording.values().end(), rb.recording.values().begin()));
    CHECK_FALSE(std::equal(ra.recording.values().begin(), ra.recording.values().end(), rc.recording.values().begin()));
    CHECK(ra.recording.frames() == 3000);
    CHECK(ra.recording.axes() == 3);

    const tjepa::SimulatedSkin& sim = a;
    const float noise_bound = static_cast<float>(3.47 * sim.config().noise_std);  // Irwin–Hall support
    std::set<int> shapes, pads;
    int contact = 0;
    std::vector<double> fn, zsum, dist, cx, lx, cy, ly;
    for (int t = 0; t < 3000; ++t) {
      const tjepa::FrameLabel& l = ra.labels[t];
      const float* f = ra.recording.frame(t);
      CHECK((l.indenter < 0) == (l.pad < 0));
      for (int i = 0; i < sim.taxels(); ++i) {
        if (sim.geometry().pad[i] == l.pad) continue;
        for (int k = 0; k < 3; ++k) {
          const float d = std::abs(f[3 * i + k] - sim.offsets()[3 * i + k]);
          if (d > noise_bound) FAIL_CHECK("frame ", t, " taxel ", i, " deviates ", d, " without contact");
        }
      }
      if (l.indenter < 0) {
        CHECK(l.force[2] == 0.0f);
        continue;
      }
      ++contact;
      shapes.insert(l.indenter);
      pads.insert(l.pad);
      CHECK(l.force[2] > 0.0f);
      CHECK(std::hypot(l.force[0], l.force[1]) <= sim.config().friction_max * l.force[2] + 1e-6);
      fn.push_back(l.force[2]);
      double z = 0;
      for (int i : sim.pad_taxels(l.pad)) z += f[3 * i + 2] - sim.offsets()[3 * i + 2];
      zsum.push_back(z);
      // Compact indenters on the flat pads: the centroid is not cut off by the pad's edge.
      if (l.force[2] > 1.0f && l.pad != 2 && l.indenter <= 1) {
        const auto cc = centroid(sim, f, l.pad);
        dist.push_back(std::hypot(cc[0] - l.location[0], cc[1] - l.location[1]));
        cx.push_back(cc[0]);
        cy.push_back(cc[1]);
        lx.push_back(l.location[0]);
        ly.push_back(l.location[1]);
      }
    }
    CHECK(shapes.size() == 4);
    CHECK(pads.size() == 3);
    CHECK(contact > 1000);
    CHECK(contact < 2900);
    CHECK(corr(fn, zsum) > 0.7);
    REQUIRE(dist.size() > 50);
    std::sort(dist.begin(), dist.end());
    CHECK(dist[dist.size() / 2] < 2.0);  // median distance between response centroid and label, mm
    CHECK(corr(cx, lx) > 0.95);
    CHECK(corr(cy, ly) > 0.95);
  }

  TEST_CASE("simulated skin: several indenters at once add their signals and the first one is labelled") {
    const auto geo = test_geometry();
    auto active_pads = [&](const tjepa::SimulatedSkin& sim, const float* f, std::set<int>& pads) {
      const float noise_bound = static_cast<float>(3.47 * sim.config().noise_std);
      pads.clear();
      for (int i = 0; i < sim.taxels(); ++i)
        for (int k = 0; k < 3; ++k)
          if (std::abs(f[3 * i + k] - sim.offsets()[3 * i + k]) > noise_bound) pads.insert(sim.geometry().pad[i]);
    };
    tjepa::SimulatedSkin one(geo, quiet_config(), 5), three(geo, quiet_config(), 5);
    const auto r1 = one.record(3000), r3 = three.record(3000, 3);
    int multi1 = 0, multi3 = 0, labelled = 0;
    std::set<int> pads;
    for (int t = 0; t < 3000; ++t) {
      active_pads(one, r1.recording.frame(t), pads);
      multi1 += pads.size() > 1;
      active_pads(three, r3.recording.frame(t), pads);
      multi3 += pads.size() > 1;
      const tjepa::FrameLabel& l = r3.labels[t];
      if (l.pad >= 0 && l.force[2] > 1.0f) {
        ++labelled;
        CHECK(pads.count(l.pad) == 1);  // the labelled indenter's pad responds
      }
    }
    CHECK(multi1 == 0);     // one indenter: one pad at a time
    CHECK(multi3 > 1000);   // three: often two or more pads at once
    CHECK(labelled > 300);
    // The first indenter's events are drawn like a single indenter's: as many labelled frames.
    int contact1 = 0, contact3 = 0;
    for (int t = 0; t < 3000; ++t) {
      contact1 += r1.labels[t].pad >= 0;
      contact3 += r3.labels[t].pad >= 0;
    }
    CHECK(std::abs(contact1 - contact3) < 600);
    CHECK_THROWS_AS(three.record(10, 0), tjepa::ConfigError);
    CHECK_THROWS_AS(three.record(10, 65), tjepa::ConfigError);
  }

  TEST_CASE("simulated skin: drop-outs are exact zeros on all axes at about the configured rate") {
    tjepa::SimConfig cfg;
    cfg.dropout_rate = 2e-3;
    cfg.dropout_frames_max = 5;
    tjepa::SimulatedSkin sim(test_geometry(), cfg, 11);
    const tjepa::Recording rec = sim.record_baseline(4000);
    std::size_t zero_taxel_frames = 0, partial = 0;
    for (int t = 0; t < rec.frames(); ++t)
      for (int i = 0; i < rec.taxels(); ++i) {
        const int zeros = (rec(t, i, 0) == 0.0f) + (rec(t, i, 1) == 0.0f) + (rec(t, i, 2) == 0.0f);
        partial += zeros == 1 || zeros == 2;
        zero_taxel_frames += zeros == 3;
      }
    CHECK(partial == 0);
    // Expected fraction: rate × mean length (3 frames), a little less where drop-outs overlap.
    const double frac = static_cast<double>(zero_taxel_frames) / (static_cast<double>(rec.frames()) * rec.taxels());
    CHECK(frac > 0.5 * 2e-3 * 3);
    CHECK(frac < 1.5 * 2e-3 * 3);
    // The magnetic preprocessing maps them (and nothing else) to 0 and removes the offsets.
    tjepa::Preprocessor pre(tjepa::PreprocessConfig::xela_counts());
    pre.fit_baseline(sim.record_baseline(500));
    auto noisy = sim.record(2000);
    pre.fit(noisy.recording);
    CHECK(pre.baseline().size() == static_cast<std::size_t>(rec.taxels()) * 3);
    for (int i = 0; i < rec.taxels(); ++i)
      CHECK(pre.baseline()[3 * i] == doctest::Approx(sim.offsets()[3 * i]).epsilon(0.01));
  }

  TEST_CASE("simulated skin: runs on the built-in Allegro/Xela layout and rejects bad input") {
    const tjepa::Skin hand = tjepa::layouts::allegro_xela();
    tjepa::SimulatedSkin sim(hand.layout, tjepa::SimConfig{}, 5);
    CHECK(sim.taxels() == 368);
    CHECK(sim.num_pads() == 18);
    const auto rec = sim.record(20000);
    CHECK(rec.recording.taxels() == 368);
    std::set<int> pads;
    for (const auto& l : rec.labels)
      if (l.pad >= 0) pads.insert(l.pad);
    CHECK(pads.size() == 18);  // ~160 contact events land on every pad
    // A grid layout converts the same way; a layout without coordinates cannot be simulated.
    const auto g = tjepa::SkinGeometry::from_layout(tjepa::layouts::grid_skin().layout);
    CHECK(g.size() == 12 * 16);
    CHECK(g.position[17][0] == doctest::Approx(4.0));
    tjepa::TaxelLayout bare = hand.layout;
    bare.dim = 0;
    bare.coords.clear();
    CHECK_THROWS_WITH_AS(tjepa::SimulatedSkin(bare, tjepa::SimConfig{}, 0), doctest::Contains("no coordinates"), tjepa::ConfigError);
    tjepa::SimConfig bad;
    bad.force_min = 5;
    bad.force_max = 1;
    CHECK_THROWS_WITH_AS(tjepa::SimulatedSkin(g, bad, 0), doctest::Contains("force range [5, 1]"), tjepa::ConfigError);
    CHECK_THROWS_AS(tjepa::SimulatedSkin(tjepa::SkinGeometry{}, {}, 0), tjepa::DataError);
    std::vector<float> small(5);
    CHECK_THROWS_AS(sim.respond(tjepa::ContactState{}, small), tjepa::ShapeError);
  }

  TEST_CASE("simulated skin: a pressure-only skin over two hands (one axis)") {
    const tjepa::Skin hands = tjepa::layouts::inspire_hands();
    tjepa::SimConfig cfg = quiet_config();
    cfg.axes = 1;
    tjepa::SimulatedSkin sim(hands.layout, cfg, 6);
    CHECK(sim.axes() == 1);
    const auto rec = sim.record(3000);
    CHECK(rec.recording.axes() == 1);
    CHECK(rec.recording.taxels() == hands.size());
    std::set<int> parts;
    int touched = 0;
    for (int t = 0; t < rec.recording.frames(); ++t) {
      const auto& l = rec.labels[t];
      if (l.pad < 0 || l.force[2] < 1.0f) continue;
      parts.insert(hands.layout.group_part[l.pad]);
      double z = 0;
      for (int i : sim.pad_taxels(l.pad)) z += rec.recording(t, i, 0) - sim.offsets()[i];
      touched += z > 0;
      CHECK(z > 0);
    }
    CHECK(touched > 100);
    CHECK(parts.size() == 2);
    tjepa::SimConfig bad;
    bad.axes = 2;
    CHECK_THROWS_WITH_AS(tjepa::SimulatedSkin(hands.layout, bad, 0), doctest::Contains("axes = 2"), tjepa::ConfigError);
  }

  TEST_CASE("preprocessor: drop-out range then baseline where non-zero then per-axis stats ignoring zeros and NaN") {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    // 3 frames, 2 taxels, 2 axes (raw counts).
    tjepa::Recording base(2, 2, 2, tjepa::AlignedVector<float>{30000, 31000, 40000, 41000,  //
                                                                30002, 70000, 40002, 41002});
    tjepa::Recording train(3, 2, 2, tjepa::AlignedVector<float>{30010, 31020, 40030, 41040,  //
                                                                100, 100, 40060, 41080,      //
                                                                30040, nan, 0, 0});
    tjepa::PreprocessConfig cfg = tjepa::PreprocessConfig::xela_counts();
    tjepa::Preprocessor pre(cfg);
    CHECK_FALSE(pre.ready());
    CHECK_THROWS_WITH_AS(pre.fit(train), doctest::Contains("fit_baseline"), tjepa::ConfigError);
    pre.fit_baseline(base);
    // 70000 is a drop-out: the axis-1 baseline of taxel 0 is the single valid reading.
    CHECK(pre.baseline() == std::vector<float>{30001, 31000, 40001, 41001});
    pre.fit(train);
    // After drop-outs and baseline, the non-zero non-NaN values per axis are:
    //   axis 0: 9, 29, 59, 39      axis 1: 20, 39, 79
    const double m0 = (9 + 29 + 59 + 39) / 4.0, m1 = (20 + 39 + 79) / 3.0;
    const double v0 = (81 + 841 + 3481 + 1521) / 4.0 - m0 * m0, v1 = (400 + 1521 + 6241) / 3.0 - m1 * m1;
    CHECK(pre.mean()[0] == doctest::Approx(m0));
    CHECK(pre.mean()[1] == doctest::Approx(m1));
    CHECK(pre.std()[0] == doctest::Approx(std::sqrt(v0)));
    CHECK(pre.std()[1] == doctest::Approx(std::sqrt(v1)));
    const tjepa::Recording out = pre.transformed(train);
    CHECK(train(0, 0, 0) == 30010.0f);  // the input is untouched (copy-on-write)
    CHECK(out(0, 0, 0) == doctest::Approx((9 - m0) / std::sqrt(v0)));
    CHECK(out(1, 0, 0) == doctest::Approx((0 - m0) / std::sqrt(v0)));  // drop-out: 0, then standardized
    CHECK(out(2, 1, 1) == doctest::Approx((0 - m1) / std::sqrt(v1)));  // zero reading: no baseline subtracted
    CHECK(std::isnan(out(2, 0, 1)));  // NaN stays NaN unless nan_as_dropout

    // State round trip: same outputs from the restored preprocessor.
    const auto state = pre.state();
    const tjepa::Preprocessor back = tjepa::Preprocessor::from_state(state);
    const tjepa::Recording out2 = back.transformed(train);
    for (std::size_t k = 0; k < out.size(); ++k)
      if (!std::isnan(out.values()[k])) CHECK(out2.values()[k] == out.values()[k]);
    std::vector<tjepa::NamedTensor> partial(state.begin(), state.begin() + 1);
    CHECK_THROWS_WITH_AS(tjepa::Preprocessor::from_state(partial), doctest::Contains("preprocess.baseline"),
                         tjepa::FileError);
    // Shape mismatch.
    tjepa::Recording other(3, 5, 2);
    CHECK_THROWS_AS(pre.apply(other), tjepa::ShapeError);
    CHECK_THROWS_AS(tjepa::Preprocessor(tjepa::PreprocessConfig::xela_counts()).apply(other), tjepa::ConfigError);
  }

  TEST_CASE("preprocessor: scalar standardization and fixed per-part maxima") {
    tjepa::Recording r(2, 3, 1, tjepa::AlignedVector<float>{1, 2, 0, 3, 4, 6});
    tjepa::Preprocessor s(tjepa::PreprocessConfig::scalar_standardization());
    s.fit(r);
    const double m = 16.0 / 5, var = (1 + 4 + 9 + 16 + 36) / 5.0 - m * m;
    CHECK(s.mean()[0] == doctest::Approx(m));
    CHECK(s.std()[0] == doctest::Approx(std::sqrt(var)));
    CHECK(s.transformed(r)(1, 2, 0) == doctest::Approx((6 - m) / std::sqrt(var)));
    tjepa::Preprocessor p(tjepa::PreprocessConfig::per_part_max({3486.0f, 4050.0f}, {0, 0, 1}));
    CHECK(p.ready());
    const auto q = p.transformed(r);
    CHECK(q(1, 1, 0) == doctest::Approx(4.0 / 3486.0));
    CHECK(q(1, 2, 0) == doctest::Approx(6.0 / 4050.0));
    CHECK(tjepa::Preprocessor::from_state(p.state()).transformed(r)(1, 2, 0) == q(1, 2, 0));
    CHECK_THROWS_AS(tjepa::Preprocessor(tjepa::PreprocessConfig::per_part_max({1.0f}, {0, 1})), tjepa::ConfigError);
    tjepa::Recording zeros(4, 2, 1);
    tjepa::Preprocessor fresh(tjepa::PreprocessConfig::scalar_standardization());
    CHECK_THROWS_WITH_AS(fresh.fit(zeros), doctest::Contains("no non-zero finite value"), tjepa::DataError);
  }

  TEST_CASE("simulated skin: reseed draws new events on the same sensor / whose baseline still applies") {
    tjepa::SimulatedSkin a(test_geometry(), tjepa::SimConfig{}, 3);
    const tjepa::Recording base = a.record_baseline(300);
    const tjepa::SimRecording first = a.record(400);
    tjepa::SimulatedSkin b(test_geometry(), tjepa::SimConfig{}, 3);
    b.reseed(11);
    CHECK(b.offsets() == a.offsets());
    const tjepa::SimRecording other = b.record(400);
    bool differ = false;
    for (std::size_t k = 0; k < other.recording.size(); ++k)
      differ = differ || other.recording.values()[k] != first.recording.values()[k];
    CHECK(differ);  // new events
    tjepa::SimulatedSkin c(test_geometry(), tjepa::SimConfig{}, 3);
    c.reseed(11);
    const tjepa::SimRecording again = c.record(400);
    CHECK(std::equal(again.recording.values().begin(), again.recording.values().end(),
                     other.recording.values().begin()));  // deterministic
    // The first sensor's no-contact baseline fits the reseeded recording, not another sensor's.
    tjepa::PreprocessConfig cfg;
    cfg.subtract_baseline = true;
    tjepa::Preprocessor with_base(cfg);
    with_base.fit_baseline(base);
    auto median_abs = [&](const tjepa::Recording& r) {
      std::vector<float> v;
      const tjepa::Recording x = with_base.transformed(r);
      for (float f : x.values())
        if (f != 0.0f) v.push_back(std::abs(f));
      std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
      return v[v.size() / 2];
    };
    tjepa::SimulatedSkin d(test_geometry(), tjepa::SimConfig{}, 4);
    CHECK(median_abs(other.recording) < 100.0f);
    CHECK(median_abs(d.record(400).recording) > 500.0f);
  }

  TEST_CASE("drift tracker: follows an idle taxel's drift / keeps a contact / passes drop-outs / round-trips") {
    // 2 taxels x 2 axes. No-contact recording: rest 30000/31000 and 40000/41000, noise ±10 counts
    // alternating (frame-to-frame differences of 20: σ = √(400 / 2) ≈ 14.1).
    tjepa::AlignedVector<float> base_v;
    for (int t = 0; t < 50; ++t) {
      const float e = t % 2 ? 10.0f : -10.0f;
      base_v.insert(base_v.end(), {30000 + e, 31000 - e, 40000 + e, 41000 + e});
    }
    tjepa::Recording base(50, 2, 2, std::move(base_v));
    tjepa::DriftTracker tr(tjepa::DriftTrackerConfig{.time_constant = 20, .threshold = 6});
    CHECK_THROWS_WITH_AS(tr.reset(), doctest::Contains("not fitted"), tjepa::ConfigError);
    tr.fit(base);
    CHECK(tr.fitted_rest()[0] == doctest::Approx(30000));
    CHECK(tr.fitted_rest()[3] == doctest::Approx(41000));
    CHECK(tr.noise()[0] == doctest::Approx(std::sqrt(200.0)).epsilon(1e-4));
    // Taxel 0 drifts up by 1 count per frame for 400 frames (slower than the tracker follows);
    // taxel 1 is pressed by +3000 counts on axis 1 during frames 200..299, then reads 0 (a drop-out)
    // during frames 300..309.
    const int T = 400;
    tjepa::Recording rec(T, 2, 2);
    for (int t = 0; t < T; ++t) {
      rec.at(t, 0, 0) = 30000.0f + static_cast<float>(t);
      rec.at(t, 0, 1) = 31000.0f + static_cast<float>(t);
      const bool pressed = t >= 200 && t < 300, dropped = t >= 300 && t < 310;
      rec.at(t, 1, 0) = dropped ? 0.0f : 40000.0f;
      rec.at(t, 1, 1) = dropped ? 0.0f : 41000.0f + (pressed ? 3000.0f : 0.0f);
    }
    const tjepa::Recording raw = rec;
    tjepa::DriftTracker copy = tr;
    tr.apply(rec);
    // The drift is gone up to the tracker's lag (time_constant x slope = 20 counts), far below the
    // 399 counts it reached; the output stays in raw counts around the fitted rest reading.
    CHECK(raw(T - 1, 0, 0) - 30000.0f == doctest::Approx(399));
    CHECK(std::abs(rec(T - 1, 0, 0) - 30000.0f) < 25.0f);
    CHECK(std::abs(rec(T - 1, 0, 1) - 31000.0f) < 25.0f);
    CHECK(tr.rest()[0] == doctest::Approx(30000.0 + 399 - 20).epsilon(1e-3));
    // The contact is kept whole: the rest reading freezes while the taxel is touched.
    for (int t = 200; t < 300; ++t) CHECK(rec(t, 1, 1) == doctest::Approx(44000));
    CHECK(tr.rest()[3] == doctest::Approx(41000));
    // Drop-outs pass unchanged.
    for (int t = 300; t < 310; ++t) CHECK(rec(t, 1, 0) == 0.0f);
    // step() frame by frame equals apply().
    tjepa::Recording again = raw;
    for (int t = 0; t < T; ++t) copy.step(again.mutable_data() + static_cast<std::size_t>(t) * 4);
    for (std::size_t k = 0; k < rec.size(); ++k) CHECK(again.values()[k] == rec.values()[k]);
    // State round trip: the restored tracker continues exactly where this one is.
    tjepa::DriftTracker back = tjepa::DriftTracker::from_state(tr.state());
    tjepa::Recording a = raw, b = raw;
    tr.apply(a);
    back.apply(b);
    for (std::size_t k = 0; k < a.size(); ++k) CHECK(a.values()[k] == b.values()[k]);
    CHECK(tjepa::DriftTracker::in_state(tr.state()));
    // reset() returns to the fitted rest reading.
    tr.reset();
    CHECK(tr.rest()[0] == tr.fitted_rest()[0]);
    // Bad input names the problem.
    auto st = tr.state();
    st[2].values.pop_back();
    CHECK_THROWS_WITH_AS(tjepa::DriftTracker::from_state(st), doctest::Contains("drift.rest0/rest/noise"),
                         tjepa::FileError);
    CHECK_THROWS_WITH_AS(tjepa::DriftTracker::from_state(std::vector<tjepa::NamedTensor>{}),
                         doctest::Contains("drift.config"), tjepa::FileError);
    tjepa::Recording wrong(3, 5, 2);
    CHECK_THROWS_AS(tr.apply(wrong), tjepa::ShapeError);
    CHECK_THROWS_WITH_AS(tr.fit(tjepa::Recording(1, 2, 2, 35000.0f)), doctest::Contains(">= 2 frames"),
                         tjepa::DataError);
    CHECK_THROWS_WITH_AS(tr.fit(tjepa::Recording(4, 2, 2, 0.0f)), doctest::Contains("no valid reading"),
                         tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::DriftTracker(tjepa::DriftTrackerConfig{.time_constant = 0.5}),
                         doctest::Contains("time_constant"), tjepa::ConfigError);
    CHECK_THROWS_WITH_AS(tjepa::DriftTracker(tjepa::DriftTrackerConfig{.threshold = -1}),
                         doctest::Contains("threshold"), tjepa::ConfigError);
  }

  TEST_CASE("drift tracker: on the simulated skin it removes most of the drift of idle taxels") {
    tjepa::SimConfig c;
    c.drift_std = 60.0;
    c.drift_time = 60.0;
    c.dropout_rate = 0.0;
    tjepa::SimulatedSkin sim(test_geometry(), c, 7);
    const tjepa::Recording base = sim.record_baseline(300);
    tjepa::Recording idle = sim.record_baseline(6000);
    tjepa::DriftTracker tr(tjepa::DriftTrackerConfig::magnetic());
    tr.fit(base);
    CHECK(tr.noise()[2] == doctest::Approx(c.noise_std).epsilon(0.1));  // drift does not count as noise
    const tjepa::Recording raw = idle;
    tr.apply(idle);
    // Mean square deviation from the fitted rest reading, over the last 5000 frames.
    double before = 0, after = 0;
    for (int t = 1000; t < 6000; ++t)
      for (int n = 0; n < raw.taxels(); ++n)
        for (int a = 0; a < 3; ++a) {
          const double b0 = tr.fitted_rest()[static_cast<std::size_t>(n) * 3 + a];
          before += (raw(t, n, a) - b0) * (raw(t, n, a) - b0);
          after += (idle(t, n, a) - b0) * (idle(t, n, a) - b0);
        }
    // What is left is the sensor noise (10 counts) plus a small lag: well under half the drift.
    const double per = 5000.0 * raw.taxels() * 3;
    MESSAGE("drift rms before ", std::sqrt(before / per), " after ", std::sqrt(after / per));
    CHECK(std::sqrt(before / per) > 40.0);
    CHECK(std::sqrt(after / per) < 0.4 * std::sqrt(before / per));
    CHECK(std::sqrt(after / per) < 20.0);
  }

  TEST_CASE("recording: frame ranges share values and copies are copy-on-write") {
    tjepa::Recording r(10, 4, 3);
    for (int t = 0; t < 10; ++t) r.at(t, 1, 2) = static_cast<float>(t);
    const tjepa::Recording train = r.frames_range(0, 8), val = r.frames_range(8, 10);
    CHECK(train.frames() == 8);
    CHECK(val(1, 1, 2) == 9.0f);
    CHECK(val.data() == r.frame(8));  // no copy
    tjepa::Recording copy = r;
    copy.at(0, 1, 2) = -1.0f;          // writes a private copy
    CHECK(r(0, 1, 2) == 0.0f);
    CHECK(train(0, 1, 2) == 0.0f);
    CHECK(copy(0, 1, 2) == -1.0f);
    CHECK_THROWS_AS(r.frames_range(5, 11), tjepa::ConfigError);
    CHECK_THROWS_AS(tjepa::Recording(2, 0, 3), tjepa::ShapeError);
    CHECK_THROWS_AS(tjepa::Recording(2, 2, 3, tjepa::AlignedVector<float>(5)), tjepa::ShapeError);
  }

  TEST_CASE("windows: starts and taxel-major copies and batches equal to preprocessing the recording") {
    CHECK(tjepa::window_starts(100, {10, 0}) == std::vector<std::int64_t>{0, 10, 20, 30, 40, 50, 60, 70, 80, 90});
    CHECK(tjepa::window_starts(25, {10, 5}) == std::vector<std::int64_t>{0, 5, 10, 15});
    CHECK(tjepa::window_starts(9, {10, 0}).empty());
    CHECK_THROWS_AS(tjepa::window_starts(9, {0, 0}), tjepa::ConfigError);

    tjepa::SimulatedSkin sim(test_geometry(), tjepa::SimConfig{}, 21);
    tjepa::Preprocessor pre(tjepa::PreprocessConfig::xela_counts());
    pre.fit_baseline(sim.record_baseline(300));
    auto data = sim.record(1000);
    pre.fit(data.recording);
    const tjepa::Recording reference = pre.transformed(data.recording);
    tjepa::WindowSource src(data.recording, {10, 0}, data.labels, pre);
    CHECK(src.size() == 100);
    const auto order = src.epoch_order(5, 0);
    CHECK(order == src.epoch_order(5, 0));
    CHECK(order != src.epoch_order(5, 1));
    std::vector<std::int64_t> sorted = order;
    std::sort(sorted.begin(), sorted.end());
    for (std::int64_t i = 0; i < src.size(); ++i) CHECK(sorted[i] == i);
    CHECK(src.batches_per_epoch(32) == 3);

    tjepa::WindowBatch batch;
    src.gather(std::span<const std::int64_t>(order).subspan(0, 8), batch);
    CHECK(batch.x.size() == 8u * sim.taxels() * 10 * 3);
    for (int b = 0; b < 8; ++b) {
      const int t0 = src.start_of(order[b]);
      for (int n = 0; n < sim.taxels(); n += 7)
        for (int j = 0; j < 10; ++j)
          for (int a = 0; a < 3; ++a)
            CHECK(batch.x[((static_cast<std::size_t>(b) * sim.taxels() + n) * 10 + j) * 3 + a] ==
                  doctest::Approx(reference(t0 + j, n, a)).epsilon(1e-5));
      const tjepa::WindowLabel l = src.label(order[b]);
      CHECK(batch.indenter[b] == l.indenter);
      CHECK(batch.force[3 * b + 2] == l.force[2]);
      float mean_fn = 0;
      for (int j = 0; j < 10; ++j) mean_fn += data.labels[t0 + j].force[2] / 10.0f;
      CHECK(l.force[2] == doctest::Approx(mean_fn));
    }
    const auto touched = src.windows_with_contact(10);
    CHECK(!touched.empty());
    for (auto i : touched) CHECK(src.label(i).indenter >= 0);
    const std::int64_t bad_id = src.size();
    CHECK_THROWS_AS(src.gather(std::span<const std::int64_t>(&bad_id, 1), batch), tjepa::ConfigError);
  }

  TEST_CASE("windows: NaN entering training is a DataError naming frame and taxel and axis") {
    tjepa::Recording rec(40, 6, 3, 1.0f);
    rec.set_source("trial.npy");
    rec.at(23, 4, 2) = std::numeric_limits<float>::quiet_NaN();
    tjepa::WindowSource src(rec, {10, 0});
    tjepa::WindowBatch batch;
    const std::vector<std::int64_t> ok = {0, 1, 3};
    CHECK_NOTHROW(src.gather(ok, batch));
    const std::vector<std::int64_t> bad = {0, 2};
    CHECK_THROWS_WITH_AS(src.gather(bad, batch), doctest::Contains("trial.npy gives nan at frame 23, taxel 4, axis 2"),
                         tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::require_finite(rec, "train"), doctest::Contains("frame 23, taxel 4, axis 2"),
                         tjepa::DataError);
    // Treating NaN as a drop-out lets it through as 0.
    tjepa::PreprocessConfig cfg;
    cfg.nan_as_dropout = true;
    tjepa::WindowSource tolerant(rec, {10, 0}, {}, tjepa::Preprocessor(cfg));
    tolerant.gather(bad, batch);
    CHECK(batch.x[((1 * 6 + 4) * 10 + 3) * 3 + 2] == 0.0f);
    CHECK_FALSE(batch.has_labels());
  }

  TEST_CASE("grouped gather: frame-major rows with padding at the end and its adjoint") {
    // B = 2, N = 5, τ = 2, m = 2; groups {4, 0}, {2, -1}, {1, 3}.
    const int B = 2, N = 5, tau = 2, m = 2, L = tau * m, G = 3, ng = 2, W = ng * L;
    std::vector<double> x(B * N * L);
    for (std::size_t k = 0; k < x.size(); ++k) x[k] = static_cast<double>(k) + 0.5;
    const auto at = [&](int b, int i, int t, int a) { return x[((b * N + i) * tau + t) * m + a]; };
    const std::vector<int> index = {4, 0, 2, -1, 1, 3};
    tjepa::check_group_index(index, G, ng, N);
    std::vector<double> out(B * G * W, -1.0);
    tjepa::gather_groups(x.data(), B, N, tau, m, index.data(), G, ng, out.data());
    // Group {2}: taxel 2's frames then zeros; groups of two: frame 0 of both members, then frame 1.
    for (int b = 0; b < B; ++b) {
      const double* row1 = out.data() + (b * G + 1) * W;
      const std::vector<double> want1 = {at(b, 2, 0, 0), at(b, 2, 0, 1), at(b, 2, 1, 0), at(b, 2, 1, 1), 0, 0, 0, 0};
      CHECK(std::vector<double>(row1, row1 + W) == want1);
      const double* row2 = out.data() + (b * G + 2) * W;
      const std::vector<double> want2 = {at(b, 1, 0, 0), at(b, 1, 0, 1), at(b, 3, 0, 0), at(b, 3, 0, 1),
                                         at(b, 1, 1, 0), at(b, 1, 1, 1), at(b, 3, 1, 0), at(b, 3, 1, 1)};
      CHECK(std::vector<double>(row2, row2 + W) == want2);
      const double* row0 = out.data() + (b * G + 0) * W;
      CHECK(row0[2] == at(b, 0, 0, 0));
      CHECK(row0[5] == at(b, 4, 1, 1));
    }
    // float windows into a double model: the same values.
    std::vector<float> xf(x.begin(), x.end());
    std::vector<double> outf(out.size());
    tjepa::gather_groups(xf.data(), B, N, tau, m, index.data(), G, ng, outf.data());
    CHECK(outf == out);
    // <gather(x), y> = <x, gather_backward(y)>
    tjepa::Rng rng(3);
    std::vector<double> y(out.size()), dx(x.size(), 0.0);
    for (auto& v : y) v = rng.normal();
    tjepa::gather_groups_backward(dx.data(), y.data(), B, N, tau, m, index.data(), G, ng);
    double lhs = 0, rhs = 0;
    for (std::size_t k = 0; k < y.size(); ++k) lhs += out[k] * y[k];
    for (std::size_t k = 0; k < x.size(); ++k) rhs += x[k] * dx[k];
    CHECK(lhs == doctest::Approx(rhs).epsilon(1e-12));
    CHECK_THROWS_WITH_AS(tjepa::check_group_index(std::vector<int>{0, 5}, 1, 2, 5), doctest::Contains("index[0][1] = 5"),
                         tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::check_group_index(std::vector<int>{0, 0}, 1, 2, 5), doctest::Contains("taxel 0 appears"),
                         tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::check_group_index(std::vector<int>{1, 2, -1, 0}, 2, 2, 5),
                         doctest::Contains("index[1][0] = -1"), tjepa::DataError);
    CHECK_THROWS_WITH_AS(tjepa::check_group_index(std::vector<int>{1, -1, 2, 0}, 1, 4, 5),
                         doctest::Contains("index[0][2] = 2 follows padding"), tjepa::DataError);
    CHECK_THROWS_AS(tjepa::check_group_index(std::vector<int>{0, 1, 2}, 2, 2, 5), tjepa::ShapeError);
  }

  TEST_CASE("grouped gather: DECO-50 rows hold each member's m values per frame in (frame*n + member)*m + axis order") {
    const tjepa::Grouping gr = tjepa::layouts::deco50_grouping(tjepa::layouts::inspire_hands());
    const int N = gr.num_taxels, G = gr.num_groups(), ng = gr.max_size, tau = 3;
    tjepa::check_group_index(gr.members, G, ng, N);
    for (int m : {1, 3}) {
      const int W = ng * tau * m;
      std::vector<double> x(static_cast<std::size_t>(N) * tau * m);
      for (int i = 0; i < N; ++i)
        for (int t = 0; t < tau; ++t)
          for (int a = 0; a < m; ++a) x[(static_cast<std::size_t>(i) * tau + t) * m + a] = 1000.0 * i + 10.0 * t + a;
      std::vector<double> out(static_cast<std::size_t>(G) * W, -1.0);
      tjepa::gather_groups(x.data(), 1, N, tau, m, gr.members.data(), G, ng, out.data());
      for (int g = 0; g < G; ++g) {
        const int n = gr.sizes[g];
        for (int c = 0; c < W; ++c) {
          const double got = out[static_cast<std::size_t>(g) * W + c];
          if (c >= n * tau * m) {
            if (got != 0.0) FAIL_CHECK("m ", m, " group ", g, " padding column ", c, " holds ", got);
            continue;
          }
          const int a = c % m, j = (c / m) % n, t = c / m / n;
          const double want = 1000.0 * gr.members[static_cast<std::size_t>(g) * ng + j] + 10.0 * t + a;
          if (got != want) FAIL_CHECK("m ", m, " group ", g, " column ", c, ": ", got, ", expected ", want);
        }
      }
    }
  }

  TEST_CASE("grouped gather into the grouped tokenizer: DECO-50 tokens are the reference's affine map and LayerNorm") {
    // The reference's DecoHypertaxelTokenizer ("direct"): x_ref [B, τ, G, 5] (member slots padded to
    // 5), token g of size n = LayerNorm(Linear_n(x_ref[b, :, g, :n].permute(1, 0).flatten())).
    const tjepa::Skin hands = tjepa::layouts::inspire_hands();
    const tjepa::Grouping gr = tjepa::layouts::deco50_grouping(hands);
    const int N = hands.size(), G = gr.num_groups(), ng = gr.max_size, tau = 3, m = 1, B = 2, d = 8;
    REQUIRE(N == 2124);
    REQUIRE(ng == 5);
    tjepa::Rng rng(11);
    std::vector<float> x(static_cast<std::size_t>(B) * N * tau * m);  // a window batch [B, N, τ, m]
    for (auto& v : x) v = static_cast<float>(rng.normal());
    std::vector<double> tokens(static_cast<std::size_t>(B) * G * ng * tau * m);
    tjepa::gather_groups(x.data(), B, N, tau, m, gr.members.data(), G, ng, tokens.data());

    tjepa::ParamSet<double> ps;
    const tjepa::Tokenizer tok = tjepa::Tokenizer::grouped(ps, gr.sizes, tau * m, d);
    ps.allocate();
    for (auto& v : ps.values()) v = rng.normal(0.0, 0.5);
    REQUIRE(tok.width == ng * tau * m);
    tjepa::Workspace<double> ws;
    std::vector<double> y(static_cast<std::size_t>(B) * G * d);
    tok.forward(ps, tokens.data(), B, y.data(), ws);

    std::vector<double> x_ref(static_cast<std::size_t>(B) * tau * G * 5, 0.0);
    for (int b = 0; b < B; ++b)
      for (int t = 0; t < tau; ++t)
        for (int g = 0; g < G; ++g)
          for (int j = 0; j < gr.sizes[g]; ++j)
            x_ref[((static_cast<std::size_t>(b) * tau + t) * G + g) * 5 + j] =
                x[(static_cast<std::size_t>(b) * N + gr.members[static_cast<std::size_t>(g) * ng + j]) * tau + t];
    int checked4 = 0, checked5 = 0;
    for (int g : {static_cast<int>(std::find(gr.sizes.begin(), gr.sizes.end(), 4) - gr.sizes.begin()),
                  static_cast<int>(std::find(gr.sizes.begin(), gr.sizes.end(), 5) - gr.sizes.begin())}) {
      REQUIRE(g < G);
      const int n = gr.sizes[g];
      (n == 4 ? checked4 : checked5) = 1;
      const std::string map = "tokenizer.direct" + std::to_string(n);
      const double* W = ps.value(ps.id(map + ".0.weight"));
      const double* bias = ps.value(ps.id(map + ".0.bias"));
      const double* gamma = ps.value(ps.id(map + ".1.weight"));
      const double* beta = ps.value(ps.id(map + ".1.bias"));
      for (int b = 0; b < B; ++b) {
        std::vector<double> v;  // x_ref[b, :, g, :n].permute(1, 0) flattened: index frame·n + member
        for (int t = 0; t < tau; ++t)
          for (int j = 0; j < n; ++j) v.push_back(x_ref[((static_cast<std::size_t>(b) * tau + t) * G + g) * 5 + j]);
        std::vector<double> h(d);
        double mean = 0, var = 0;
        for (int o = 0; o < d; ++o) {
          h[o] = bias[o];
          for (int c = 0; c < n * tau; ++c) h[o] += W[o * n * tau + c] * v[c];
          mean += h[o] / d;
        }
        for (int o = 0; o < d; ++o) var += (h[o] - mean) * (h[o] - mean) / d;
        for (int o = 0; o < d; ++o) {
          const double want = (h[o] - mean) / std::sqrt(var + 1e-6) * gamma[o] + beta[o];
          CHECK(y[(static_cast<std::size_t>(b) * G + g) * d + o] == doctest::Approx(want).epsilon(1e-12));
        }
      }
    }
    CHECK(checked4 + checked5 == 2);
  }

  TEST_CASE("simulate_dataset: train and validation sources with statistics fitted on training data only") {
    tjepa::SimulatedDatasetOptions opt;
    opt.train_windows = 300;
    opt.validation_windows = 50;
    auto data = tjepa::simulate_dataset(tjepa::layouts::allegro_xela().layout, opt, 9);
    CHECK(data.train.size() == 300);
    CHECK(data.validation.size() == 50);
    CHECK(data.train.has_labels());
    CHECK(data.preprocessor.ready());
    // The statistics are those of the training recording: refitting on it reproduces them.
    // The statistics are the training recording's, not the validation recording's.
    tjepa::Preprocessor direct = tjepa::Preprocessor::from_state(data.preprocessor.state());
    direct.fit(data.train.recordings()[0]);
    CHECK(direct.mean() == data.preprocessor.mean());
    CHECK(direct.std() == data.preprocessor.std());
    direct.fit(data.validation.recordings()[0]);
    CHECK(direct.mean() != data.preprocessor.mean());
    // Standardized training batches: per-axis mean near 0 and std near 1 over the non-drop-out values.
    tjepa::WindowBatch b;
    const auto order = data.train.epoch_order(1, 0);
    data.train.gather(std::span<const std::int64_t>(order).subspan(0, 128), b);
    double s[3] = {0, 0, 0}, q[3] = {0, 0, 0};
    for (std::size_t k = 0; k < b.x.size(); ++k) {
      s[k % 3] += b.x[k];
      q[k % 3] += static_cast<double>(b.x[k]) * b.x[k];
    }
    const double n = static_cast<double>(b.x.size()) / 3;
    for (int a = 0; a < 3; ++a) {
      CHECK(std::abs(s[a] / n) < 0.1);
      CHECK(std::sqrt(q[a] / n) == doctest::Approx(1.0).epsilon(0.1));
    }
    // Same seed, same data.
    auto again = tjepa::simulate_dataset(tjepa::layouts::allegro_xela().layout, opt, 9);
    CHECK(std::equal(again.validation.recordings()[0].values().begin(), again.validation.recordings()[0].values().end(),
                     data.validation.recordings()[0].values().begin()));
  }
}
