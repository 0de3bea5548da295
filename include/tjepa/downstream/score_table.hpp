#pragma once
// A table of scores: rows (methods, encoders, read-outs) × metrics, each cell the runs of
// [sample][head], where a sample is the unit the spread is taken over (a pre-training seed in the
// protocol, a probe's repeat in `tjepa probe`) and heads are averaged inside it. Its statistics:
//   per sample, the mean over its heads                    (one value per sample)
//   per row, the mean and the sample sd of those values    (n = number of samples)
//   per primary metric, a one-sided Welch t-test of the best row against the second best
//   (H1: the best is better), on those values
// and three renderings: markdown, JSON (every run), and an SVG bar chart with sd error bars.
// `tjepa eval` and `tjepa demo` (eval/grasp_eval.hpp), `tjepa probe` and its label probe all
// report through it.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tjepa/core/error.hpp"
#include "tjepa/downstream/welch.hpp"
#include "tjepa/graph/svg.hpp"

namespace tjepa {

struct ScoreMetric {
  std::string key;   // JSON key
  std::string name;  // column title
  std::string unit;  // shown after the name in parentheses ("" for none)
  bool higher_is_better = true;
  bool primary = true;  // compared (Welch) and drawn
  double scale = 1;     // shown (not stored) as value · scale: 100 for a fraction as percent
  std::string format = "%.3g", sd_format = "%.2g";
};

struct ScoreRow {
  std::string name;
  std::vector<std::vector<std::vector<double>>> runs;  // [sample][head][metric]
  std::vector<std::string> cells;                      // the table's extra columns
  std::string note;                                    // why the row says little ("" = nothing to say)
  nlohmann::json info = nlohmann::json::object();      // more about the row, merged into its JSON

  // Adds one sample: its heads' scores, each a range of one value per metric.
  template <class Scores>
  void add_sample(const std::vector<Scores>& heads) {
    std::vector<std::vector<double>> s;
    for (const Scores& h : heads) s.emplace_back(std::begin(h), std::end(h));
    runs.push_back(std::move(s));
  }

  // The head-averaged value of metric m for each sample.
  std::vector<double> samples(int m) const {
    std::vector<double> out;
    for (const auto& heads : runs) {
      require<DataError>(!heads.empty(), "ScoreRow ", name, ": a sample without head runs");
      double sum = 0;
      for (const auto& s : heads) {
        require<ShapeError>(static_cast<std::size_t>(m) < s.size(), "ScoreRow ", name, ": a run of ", s.size(),
                            " scores, metric ", m, " asked for");
        sum += s[static_cast<std::size_t>(m)];
      }
      out.push_back(sum / static_cast<double>(heads.size()));
    }
    return out;
  }
  // Mean and sd over the samples; n = 0 without any, mean NaN when a sample is not finite.
  SampleSummary summary(int m) const {
    const std::vector<double> x = samples(m);
    if (x.empty()) return {std::numeric_limits<double>::quiet_NaN(), 0, 0};
    for (double v : x)
      if (!std::isfinite(v))
        return {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::quiet_NaN(), static_cast<int>(x.size())};
    return summarize(x);
  }
};

struct ScoreComparison {
  int metric = 0;
  int best = -1, second = -1;  // row indices
  WelchResult test;            // one-sided: best better than second; p = 1 when untestable
  bool tested = false;         // both rows have >= 2 samples
};

struct ScoreTable {
  std::string title;
  std::vector<ScoreMetric> metrics;
  std::vector<ScoreRow> rows;
  std::string row_header = "method";  // the first column's title
  std::string sample_name = "seeds";  // what a sample is (plural): the JSON key of the samples
  std::vector<std::string> columns;   // extra text columns after the metrics (ScoreRow::cells)
  bool note_column = false;           // a "note" column (otherwise notes follow the table)
  // Named pairs to test beside the best two, (a, b): H1 "a is better than b" per primary metric
  // (e.g. a pre-trained encoder against its random initialization). A pair naming a row the table
  // does not have is left out.
  std::vector<std::pair<std::string, std::string>> contrasts;

  int metric(const std::string& key) const {
    for (std::size_t m = 0; m < metrics.size(); ++m)
      if (metrics[m].key == key) return static_cast<int>(m);
    throw ConfigError("ScoreTable " + title + ": no metric '" + key + "'");
  }

  // The row called name, added (empty) when there is none.
  ScoreRow& row(const std::string& name) {
    for (ScoreRow& r : rows)
      if (r.name == name) return r;
    rows.push_back(ScoreRow{name, {}, {}, {}, nlohmann::json::object()});
    return rows.back();
  }

  // For each primary metric: the two rows with the best means (rows with a finite mean), and
  // Welch's test between them.
  std::vector<ScoreComparison> comparisons() const {
    std::vector<ScoreComparison> out;
    for (int m = 0; m < static_cast<int>(metrics.size()); ++m) {
      const ScoreMetric& g = metrics[static_cast<std::size_t>(m)];
      if (!g.primary) continue;
      std::vector<int> order;
      std::vector<double> mean;
      for (int r = 0; r < static_cast<int>(rows.size()); ++r) {
        mean.push_back(rows[static_cast<std::size_t>(r)].summary(m).mean);
        if (std::isfinite(mean.back())) order.push_back(r);
      }
      if (order.size() < 2) continue;
      std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
        return g.higher_is_better ? mean[a] > mean[b] : mean[a] < mean[b];
      });
      out.push_back(compare(m, order[0], order[1]));
    }
    return out;
  }

  // Welch's one-sided test of row a against row b on metric m (H1: a is better).
  ScoreComparison compare(int m, int a, int b) const {
    const ScoreMetric& g = metrics[static_cast<std::size_t>(m)];
    ScoreComparison c;
    c.metric = m;
    c.best = a;
    c.second = b;
    const auto x = rows[static_cast<std::size_t>(a)].samples(m), y = rows[static_cast<std::size_t>(b)].samples(m);
    c.tested = x.size() >= 2 && y.size() >= 2;
    if (c.tested) c.test = welch_t_test(x, y, g.higher_is_better ? Alternative::greater : Alternative::less);
    else c.test.p = 1.0;
    return c;
  }

  // The named contrasts' tests, per primary metric (best: the pair's first row, second: its other).
  std::vector<ScoreComparison> contrast_tests() const {
    std::vector<ScoreComparison> out;
    auto index = [&](const std::string& name) {
      for (std::size_t r = 0; r < rows.size(); ++r)
        if (rows[r].name == name && !rows[r].runs.empty()) return static_cast<int>(r);
      return -1;
    };
    for (const auto& [a, b] : contrasts) {
      const int ia = index(a), ib = index(b);
      if (ia < 0 || ib < 0) continue;
      for (int m = 0; m < static_cast<int>(metrics.size()); ++m)
        if (metrics[static_cast<std::size_t>(m)].primary) out.push_back(compare(m, ia, ib));
    }
    return out;
  }

  // "mean ± sd" (sd with two samples or more), "-" for a row without samples.
  std::string cell(const ScoreRow& r, int m) const {
    const ScoreMetric& g = metrics[static_cast<std::size_t>(m)];
    const SampleSummary s = r.summary(m);
    if (s.n == 0) return "-";
    char buf[96];
    std::snprintf(buf, sizeof buf, g.format.c_str(), s.mean * g.scale);
    std::string out = buf;
    if (s.n >= 2) {
      std::snprintf(buf, sizeof buf, g.sd_format.c_str(), s.sd * g.scale);
      out += std::string(" ± ") + buf;
    }
    return out;
  }

  std::string markdown() const {
    std::ostringstream o;
    char buf[64];
    if (!title.empty()) o << "### " << title << "\n\n";
    o << "| " << row_header << " |";
    for (const ScoreMetric& g : metrics)
      o << " " << g.name << (g.unit.empty() ? "" : " (" + g.unit + ")") << " " << (g.higher_is_better ? "↑" : "↓") << " |";
    for (const std::string& c : columns) o << " " << c << " |";
    if (note_column) o << " note |";
    o << "\n|---|";
    for (std::size_t i = 0; i < metrics.size() + columns.size() + note_column; ++i) o << "---|";
    o << "\n";
    for (const ScoreRow& r : rows) {
      o << "| " << r.name << " |";
      for (int m = 0; m < static_cast<int>(metrics.size()); ++m) o << " " << cell(r, m) << " |";
      for (std::size_t c = 0; c < columns.size(); ++c)
        o << (c < r.cells.size() && !r.cells[c].empty() ? " " + r.cells[c] + " |" : std::string(" |"));
      if (note_column) o << (r.note.empty() ? std::string(" |") : " **" + r.note + "** |");
      o << "\n";
    }
    if (!note_column)
      for (const ScoreRow& r : rows)
        if (!r.note.empty()) o << "note: " << r.name << ": " << r.note << "\n";
    const auto cmp = comparisons();
    const auto named = contrast_tests();
    if (!cmp.empty() || !named.empty()) o << "\n";
    for (std::size_t k = 0; k < cmp.size() + named.size(); ++k) {
      const bool best_two = k < cmp.size();
      const ScoreComparison& c = best_two ? cmp[k] : named[k - cmp.size()];
      const ScoreMetric& g = metrics[static_cast<std::size_t>(c.metric)];
      o << "- " << g.name << (best_two ? ": best " : ": ") << rows[static_cast<std::size_t>(c.best)].name
        << (best_two ? ", second " : " against ") << rows[static_cast<std::size_t>(c.second)].name;
      if (c.tested) {
        std::snprintf(buf, sizeof buf, "%.3g", c.test.p);
        o << "; one-sided Welch t = " << c.test.t << ", df = " << c.test.df << ", p = " << buf;
      } else {
        o << "; not tested (fewer than 2 " << sample_name << ")";
      }
      o << "\n";
    }
    return o.str();
  }

  // {title, metrics, rows: [{name, mean, sd, <sample_name>, runs, note?, ...info}], comparisons};
  // a metric without samples is left out of mean, sd and <sample_name>.
  nlohmann::json to_json() const {
    nlohmann::json j = {{"title", title}, {"metrics", nlohmann::json::array()}, {"rows", nlohmann::json::array()},
                        {"comparisons", nlohmann::json::array()}};
    for (const ScoreMetric& g : metrics)
      j["metrics"].push_back({{"key", g.key}, {"name", g.name}, {"unit", g.unit}, {"higher_is_better", g.higher_is_better},
                              {"primary", g.primary}});
    auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
    for (const ScoreRow& r : rows) {
      nlohmann::json row = {{"name", r.name}, {"mean", nlohmann::json::object()}, {"sd", nlohmann::json::object()},
                            {sample_name, nlohmann::json::object()}, {"runs", nlohmann::json::array()}};
      for (int m = 0; m < static_cast<int>(metrics.size()); ++m) {
        const std::string& k = metrics[static_cast<std::size_t>(m)].key;
        const SampleSummary s = r.summary(m);
        if (s.n == 0) continue;
        row["mean"][k] = number(s.mean);
        row["sd"][k] = number(s.sd);
        nlohmann::json x = nlohmann::json::array();
        for (double v : r.samples(m)) x.push_back(number(v));
        row[sample_name][k] = x;
      }
      for (const auto& heads : r.runs) {
        nlohmann::json sample = nlohmann::json::array();
        for (const auto& s : heads) {
          nlohmann::json h;
          for (std::size_t m = 0; m < metrics.size() && m < s.size(); ++m) h[metrics[m].key] = number(s[m]);
          sample.push_back(h);
        }
        row["runs"].push_back(sample);
      }
      if (!r.note.empty()) row["note"] = r.note;
      row.update(r.info);
      j["rows"].push_back(row);
    }
    for (const ScoreComparison& c : comparisons())
      j["comparisons"].push_back({{"metric", metrics[static_cast<std::size_t>(c.metric)].key},
                                  {"best", rows[static_cast<std::size_t>(c.best)].name},
                                  {"second", rows[static_cast<std::size_t>(c.second)].name},
                                  {"tested", c.tested}, {"t", c.test.t}, {"df", c.test.df}, {"p", c.test.p}});
    for (const ScoreComparison& c : contrast_tests())
      j["contrasts"].push_back({{"metric", metrics[static_cast<std::size_t>(c.metric)].key},
                                {"row", rows[static_cast<std::size_t>(c.best)].name},
                                {"against", rows[static_cast<std::size_t>(c.second)].name},
                                {"tested", c.tested}, {"t", c.test.t}, {"df", c.test.df}, {"p", c.test.p}});
    return j;
  }

  // One panel per primary metric: a horizontal bar per row at its mean, the sd as an error bar.
  std::string svg() const {
    const int panel_w = 300, bar_h = 16, label_w = 190, pad = 10;
    int panels = 0;
    for (const ScoreMetric& g : metrics) panels += g.primary;
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
    for (int m = 0; m < static_cast<int>(metrics.size()); ++m) {
      const ScoreMetric& g = metrics[static_cast<std::size_t>(m)];
      if (!g.primary) continue;
      const int x0 = label_w + p++ * (panel_w + pad);
      double top = 0;
      for (const ScoreRow& r : rows) {
        const SampleSummary s = r.summary(m);
        if (s.n > 0 && std::isfinite(s.mean)) top = std::max(top, s.mean + s.sd);
      }
      if (!(top > 0)) top = 1;
      std::snprintf(buf, sizeof buf, "%s (%s, %s)", g.name.c_str(), g.unit.c_str(),
                    g.higher_is_better ? "higher is better" : "lower is better");
      o << "<text x=\"" << x0 << "\" y=\"42\">" << xml_escape(buf) << "</text>\n";
      o << "<line x1=\"" << x0 << "\" y1=\"50\" x2=\"" << x0 << "\" y2=\"" << 50 + rows_n * (bar_h + 4) + 6
        << "\" stroke=\"black\"/>\n";
      for (int r = 0; r < rows_n; ++r) {
        const SampleSummary s = rows[static_cast<std::size_t>(r)].summary(m);
        if (s.n == 0 || !std::isfinite(s.mean)) continue;
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
