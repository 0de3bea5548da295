#pragma once
// The results table of the downstream protocol: rows (methods) × the grasp tasks' metrics, each
// cell the runs of [pre-training seed][head seed]. The protocol's statistics:
//   per pre-training seed, the mean over its heads        (one sample per seed)
//   per row, the mean and the sample sd of those samples   (n = number of seeds)
//   per primary metric, a one-sided Welch t-test of the best row against the second best
//   (H1: the best is better), on those samples
// and three renderings: markdown, JSON (every run), and an SVG bar chart with sd error bars.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/eval/grasp_tasks.hpp"
#include "tjepa/downstream/welch.hpp"
#include "tjepa/graph/svg.hpp"

namespace tjepa {

struct EvalRow {
  std::string name;
  std::vector<std::vector<GraspScores>> runs;  // [pre-training seed][head seed]

  // The head-averaged value of metric m for each pre-training seed.
  std::vector<double> samples(int m) const {
    std::vector<double> out;
    for (const auto& heads : runs) {
      require<DataError>(!heads.empty(), "EvalRow ", name, ": a seed without head runs");
      double sum = 0;
      for (const GraspScores& s : heads) sum += s[static_cast<std::size_t>(m)];
      out.push_back(sum / static_cast<double>(heads.size()));
    }
    return out;
  }
  SampleSummary summary(int m) const { return summarize(samples(m)); }
};

struct EvalComparison {
  int metric = 0;
  int best = -1, second = -1;  // row indices
  WelchResult test;            // one-sided: best better than second; p = 1 when untestable
  bool tested = false;         // both rows have >= 2 seeds
};

struct EvalTable {
  std::string title;
  std::vector<EvalRow> rows;

  // For each primary metric: the two rows with the best means, and Welch's test between them.
  std::vector<EvalComparison> comparisons() const {
    std::vector<EvalComparison> out;
    if (rows.size() < 2) return out;
    for (int m = 0; m < static_cast<int>(grasp_metrics.size()); ++m) {
      const GraspMetric& g = grasp_metrics[static_cast<std::size_t>(m)];
      if (!g.primary) continue;
      std::vector<int> order(rows.size());
      std::iota(order.begin(), order.end(), 0);
      std::vector<double> mean;
      for (const EvalRow& r : rows) mean.push_back(r.summary(m).mean);
      std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
        return g.higher_is_better ? mean[a] > mean[b] : mean[a] < mean[b];
      });
      EvalComparison c;
      c.metric = m;
      c.best = order[0];
      c.second = order[1];
      const auto a = rows[c.best].samples(m), b = rows[c.second].samples(m);
      c.tested = a.size() >= 2 && b.size() >= 2;
      if (c.tested) c.test = welch_t_test(a, b, g.higher_is_better ? Alternative::greater : Alternative::less);
      else c.test.p = 1.0;
      out.push_back(c);
    }
    return out;
  }

  std::string markdown() const {
    std::ostringstream o;
    char buf[64];
    auto cell = [&](const EvalRow& r, int m) {
      const SampleSummary s = r.summary(m);
      if (s.n >= 2) std::snprintf(buf, sizeof buf, "%.3g ± %.2g", s.mean, s.sd);
      else std::snprintf(buf, sizeof buf, "%.3g", s.mean);
      return std::string(buf);
    };
    if (!title.empty()) o << "### " << title << "\n\n";
    o << "| method |";
    for (const GraspMetric& g : grasp_metrics) o << " " << g.name << " (" << g.unit << ") " << (g.higher_is_better ? "↑" : "↓") << " |";
    o << "\n|---|";
    for (std::size_t i = 0; i < grasp_metrics.size(); ++i) o << "---|";
    o << "\n";
    for (const EvalRow& r : rows) {
      o << "| " << r.name << " |";
      for (int m = 0; m < static_cast<int>(grasp_metrics.size()); ++m) o << " " << cell(r, m) << " |";
      o << "\n";
    }
    const auto cmp = comparisons();
    if (!cmp.empty()) o << "\n";
    for (const EvalComparison& c : cmp) {
      const GraspMetric& g = grasp_metrics[static_cast<std::size_t>(c.metric)];
      o << "- " << g.name << ": best " << rows[c.best].name << ", second " << rows[c.second].name;
      if (c.tested) {
        std::snprintf(buf, sizeof buf, "%.3g", c.test.p);
        o << "; one-sided Welch t = " << c.test.t << ", df = " << c.test.df << ", p = " << buf;
      } else {
        o << "; not tested (fewer than 2 seeds)";
      }
      o << "\n";
    }
    return o.str();
  }

  nlohmann::json to_json() const {
    nlohmann::json j = {{"title", title}, {"metrics", nlohmann::json::array()}, {"rows", nlohmann::json::array()},
                        {"comparisons", nlohmann::json::array()}};
    for (const GraspMetric& g : grasp_metrics)
      j["metrics"].push_back({{"key", g.key}, {"name", g.name}, {"unit", g.unit}, {"higher_is_better", g.higher_is_better},
                              {"primary", g.primary}});
    for (const EvalRow& r : rows) {
      nlohmann::json row = {{"name", r.name}, {"mean", nlohmann::json::object()}, {"sd", nlohmann::json::object()},
                            {"seeds", nlohmann::json::object()}, {"runs", nlohmann::json::array()}};
      for (int m = 0; m < static_cast<int>(grasp_metrics.size()); ++m) {
        const char* k = grasp_metrics[static_cast<std::size_t>(m)].key;
        const SampleSummary s = r.summary(m);
        row["mean"][k] = s.mean;
        row["sd"][k] = s.sd;
        row["seeds"][k] = r.samples(m);
      }
      for (const auto& heads : r.runs) {
        nlohmann::json seed = nlohmann::json::array();
        for (const GraspScores& s : heads) {
          nlohmann::json h;
          for (std::size_t m = 0; m < grasp_metrics.size(); ++m) h[grasp_metrics[m].key] = s[m];
          seed.push_back(h);
        }
        row["runs"].push_back(seed);
      }
      j["rows"].push_back(row);
    }
    for (const EvalComparison& c : comparisons())
      j["comparisons"].push_back({{"metric", grasp_metrics[static_cast<std::size_t>(c.metric)].key},
                                  {"best", rows[c.best].name}, {"second", rows[c.second].name},
                                  {"tested", c.tested}, {"t", c.test.t}, {"df", c.test.df}, {"p", c.test.p}});
    return j;
  }

  // One panel per primary metric: a horizontal bar per row at its mean, the sd as an error bar.
  std::string svg() const {
    const int panel_w = 300, bar_h = 16, label_w = 190, pad = 10;
    int panels = 0;
    for (const GraspMetric& g : grasp_metrics) panels += g.primary;
    const int rows_n = static_cast<int>(rows.size());
    const int panel_h = 40 + rows_n * (bar_h + 4);
    const int width = label_w + panels * (panel_w + pad) + pad, height = panel_h + 40;
    std::ostringstream o;
    char buf[160];
    o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
      << "\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
    o << "<text x=\"" << pad << "\" y=\"18\" font-size=\"13\">" << xml_escape(title) << "</text>\n";
    for (int r = 0; r < rows_n; ++r)
      o << "<text x=\"" << label_w - 6 << "\" y=\"" << 60 + r * (bar_h + 4) + bar_h - 4 << "\" text-anchor=\"end\">"
        << xml_escape(rows[static_cast<std::size_t>(r)].name) << "</text>\n";
    int p = 0;
    static const char* colors[] = {"#999999", "#bbbbbb", "#8da0cb", "#fc8d62", "#66c2a5", "#e78ac3", "#a6d854", "#ffd92f"};
    for (int m = 0; m < static_cast<int>(grasp_metrics.size()); ++m) {
      const GraspMetric& g = grasp_metrics[static_cast<std::size_t>(m)];
      if (!g.primary) continue;
      const int x0 = label_w + p++ * (panel_w + pad);
      double top = 0;
      for (const EvalRow& r : rows) {
        const SampleSummary s = r.summary(m);
        top = std::max(top, s.mean + s.sd);
      }
      if (!(top > 0)) top = 1;
      std::snprintf(buf, sizeof buf, "%s (%s, %s)", g.name, g.unit, g.higher_is_better ? "higher is better" : "lower is better");
      o << "<text x=\"" << x0 << "\" y=\"42\">" << xml_escape(buf) << "</text>\n";
      o << "<line x1=\"" << x0 << "\" y1=\"50\" x2=\"" << x0 << "\" y2=\"" << 50 + rows_n * (bar_h + 4) + 6
        << "\" stroke=\"black\"/>\n";
      for (int r = 0; r < rows_n; ++r) {
        const SampleSummary s = rows[static_cast<std::size_t>(r)].summary(m);
        const double scale = (panel_w - 50) / top;
        const int y = 56 + r * (bar_h + 4);
        std::snprintf(buf, sizeof buf, "<rect x=\"%d\" y=\"%d\" width=\"%.1f\" height=\"%d\" fill=\"%s\"/>\n", x0, y,
                      s.mean * scale, bar_h, colors[r % 8]);
        o << buf;
        if (s.n >= 2 && s.sd > 0) {
          std::snprintf(buf, sizeof buf, "<line x1=\"%.1f\" y1=\"%d\" x2=\"%.1f\" y2=\"%d\" stroke=\"black\"/>\n",
                        x0 + (s.mean - s.sd) * scale, y + bar_h / 2, x0 + (s.mean + s.sd) * scale, y + bar_h / 2);
          o << buf;
        }
        std::snprintf(buf, sizeof buf, "<text x=\"%.1f\" y=\"%d\">%.3g</text>\n", x0 + (s.mean + s.sd) * scale + 4,
                      y + bar_h - 4, s.mean);
        o << buf;
      }
    }
    o << "</svg>\n";
    return o.str();
  }
};

}  // namespace tjepa
