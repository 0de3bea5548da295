#pragma once
// tjepa run: a pre-trained encoder and a trained head (`tjepa probe --task ... --save`) on a live
// source, one frame at a time (the library's Pipeline), predictions out as windows complete:
//
//   tjepa run --model run.safetensors --head head.safetensors --source ws://127.0.0.1:5000
//             | serial:/dev/ttyACM0[@115200] | replay:rec.npy  [--out predictions.csv]
//
// Frames arrive in the sensor's order (the recording's columns; the model's taxel order maps them
// to its layout). A gap the source reports (reconnect, malformed message, wrong taxel count, a
// jump of the sensor's clock) restarts the window. At the end (the source ended, --frames reached,
// or Ctrl-C): the problems counted by kind, the latency of the frames that complete a window
// (p50 / p99 / max), and the heap allocations after the first window, the pipeline's and the
// source's apart. --out: one row per window (window, frame, time, gap, then the class and its
// probabilities, or the regression outputs), written atomically at the end.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include <allocation_counter.hpp>
#include <tjepa/downstream/pipeline.hpp>
#include <tjepa/tjepa.hpp>

#include "options.hpp"
#include "output.hpp"
#include "setup.hpp"
#include "sources/anyskin.hpp"
#include "sources/replay.hpp"
#include "sources/xserver.hpp"

namespace tjepa::cli {

struct RunOptions {
  std::string model, head, source, out;
  std::string encoder = "target";
  std::string precision = "fp32";
  int stride = 0;           // 0: the head's (1 without a head)
  std::int64_t frames = 0;  // stop after this many frames (0: when the source ends)
  double rate = 100;        // replay: frames per second (0: back to back); xServer: the sensor's rate
  int reconnects = -1;      // xServer / serial: reconnect attempts after a drop (−1: for ever)
  double backoff = 0.1;     // first wait before reconnecting, seconds (doubling up to 5 s)
  double idle_timeout = 2;  // xServer: seconds without a message before the connection is dropped
  DataFormat format;        // replay: how the recording is read
  bool force = false;
};

namespace detail_run {
inline std::atomic<FrameSource*> active_source{nullptr};
inline void on_interrupt(int) {
  if (FrameSource* s = active_source.load()) s->stop();
}
}  // namespace detail_run

// The source a --source names, for a model of `taxels` × `axes`.
inline std::unique_ptr<FrameSource> open_source(const RunOptions& o, int taxels, int axes) {
  const std::string& s = o.source;
  if (s.starts_with("replay:")) {
    const std::string file = s.substr(7);
    return std::make_unique<ReplaySource>(read_recording(file, o.format), o.rate);
  }
  if (s.starts_with("ws://")) {
    XServerOptions x = parse_ws_url(s);
    x.taxels = taxels;
    x.axes = axes;
    x.rate = o.rate > 0 ? o.rate : 100;
    x.reconnects = o.reconnects;
    x.backoff_s = o.backoff;
    x.idle_timeout_s = o.idle_timeout;
    return std::make_unique<XServerSource>(x);
  }
  if (s.starts_with("serial:")) {
    std::string device = s.substr(7);
    int baud = 115200;
    if (const auto at = device.rfind('@'); at != std::string::npos) {
      const std::string b = device.substr(at + 1);
      require<ConfigError>(!b.empty() && b.find_first_not_of("0123456789") == std::string::npos && b.size() < 8,
                           "--source '", s, "': baud '", b, "', expected a number");
      baud = std::stoi(b);
      device = device.substr(0, at);
    }
    require<ConfigError>(!device.empty(), "--source '", s, "': no device");
    return std::make_unique<AnySkinSource>(device, baud, taxels, axes, o.reconnects, o.backoff);
  }
  fail<ConfigError>("--source '", s, "': expected replay:FILE, ws://HOST[:PORT] (XELA's xServer) or "
                    "serial:DEVICE[@BAUD] (AnySkin)");
}

inline double quantile_of(std::vector<double>& v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

inline int run_live(const RunOptions& o, std::ostream& out) {
  require<ConfigError>(!o.model.empty() && !o.source.empty(), "--model and --source are required");
  require<ConfigError>(o.out.empty() || !o.head.empty(), "--out writes the head's predictions: give --head");
  require<ConfigError>(o.encoder == "target" || o.encoder == "context", "--encoder '", o.encoder,
                       "', expected target or context");
  require<ConfigError>(o.precision == "fp32" || o.precision == "bf16", "--precision '", o.precision,
                       "', expected fp32 or bf16");
  require<ConfigError>(o.frames >= 0 && o.stride >= 0, "--frames ", o.frames, ", --stride ", o.stride,
                       ", expected >= 0");
  require<ConfigError>(o.source.starts_with("replay:") || (o.format.columns.empty() && o.format.lines_per_frame == 1),
                       "--columns and --lines-per-frame are for replay:FILE, not for '", o.source, "'");
  if (!o.out.empty()) OutputFiles::check_new(o.out, o.force);
  TrainedModel m = load_trained_model(o.model);
  const Skin skin = load_skin(SkinSpec::of(m.config));
  std::optional<LoadedProbeHead<float>> head;
  if (!o.head.empty()) head = load_probe_head<float>(o.head);
  PipelineConfig pc;
  pc.column = skin.layout.column;
  pc.stride = o.stride;
  pc.target_encoder = o.encoder == "target";
  pc.precision = o.precision == "bf16" ? Precision::bf16 : Precision::fp32;
  Pipeline pipe(std::move(m), std::move(head), pc);
  const int N = pipe.taxels(), axes = pipe.axes();
  std::unique_ptr<FrameSource> source = open_source(o, N, axes);

  const auto& h = pipe.head();
  const HeadInfo* info = h ? &h->info : nullptr;
  const int R = h ? h->head.regression : 0, C = h ? h->head.classes : 0;
  out << "run: " << source->describe() << "\n     " << N << " taxels x " << axes << " axes, windows of " << pipe.tau()
      << " frames every " << pipe.stride() << ", the " << o.encoder << " encoder in "
      << precision_name(effective_precision(pc.precision));
  if (info)
    out << ", head: " << (info->task.empty() ? std::string("probe") : info->task) << " ("
        << (C > 0 ? std::to_string(C) + " classes" : std::to_string(R) + " outputs") << ")";
  out << "\n";
  if (pc.precision == Precision::bf16)
    if (const std::string why = bf16_slower_reason(measure_product_peaks()); !why.empty())
      out << "note: --precision bf16: " << why << "\n";

  std::vector<float> frame(static_cast<std::size_t>(N) * axes);
  std::vector<double> latency_us;
  latency_us.reserve(1 << 16);
  std::int64_t frames = 0, windows = 0, restarts = 0;
  long pipeline_allocations = 0, source_allocations = 0;
  bool warm = false;
  using Clock = std::chrono::steady_clock;

  auto loop = [&](std::ostream* csv) {
    char line[256];
    if (csv) {
      *csv << "window,frame,time,gap";
      if (C > 0) *csv << ",prediction";
      for (int c = 0; c < C; ++c) *csv << ",p_" << csv_field(info->class_names[static_cast<std::size_t>(c)]);
      for (int r = 0; r < R; ++r)
        *csv << "," << (static_cast<std::size_t>(r) < info->output_names.size() ? csv_field(info->output_names[static_cast<std::size_t>(r)])
                                                                              : "output_" + std::to_string(r));
      *csv << "\n";
    }
    detail_run::active_source = source.get();
    const auto previous = std::signal(SIGINT, detail_run::on_interrupt);
    alloc::start();
    bool gap_pending = false;
    try {
      while (o.frames == 0 || frames < o.frames) {
        FrameInfo fi;
        const long a0 = alloc::allocations.load();
        if (!source->next(frame, fi)) break;
        const long a1 = alloc::allocations.load();
        if (frames == 0) {  // raw counts into a model that expects them baseline-subtracted: said once
          Recording first(1, N, axes);
          std::copy(frame.begin(), frame.end(), first.mutable_data());
          raw_counts_warning(pipe.model(), std::span<const Recording>(&first, 1), out);
        }
        if (fi.gap) {
          pipe.restart();
          ++restarts;
          gap_pending = true;
        }
        const auto t0 = Clock::now();
        const PipelineOutput* y = pipe.push(frame);
        const auto t1 = Clock::now();
        const long a2 = alloc::allocations.load();
        ++frames;
        if (warm) {
          source_allocations += a1 - a0;
          pipeline_allocations += a2 - a1;
        }
        if (!y) continue;
        if (warm) latency_us.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
        warm = true;  // from the first window on, the pipeline is warm
        if (csv) {
          int n = std::snprintf(line, sizeof line, "%lld,%lld,%.6f,%d", static_cast<long long>(windows),
                                static_cast<long long>(y->frame), fi.time, gap_pending ? 1 : 0);
          csv->write(line, n);
          if (C > 0) {
            const std::string& name = info->class_names[static_cast<std::size_t>(y->label)];
            csv->put(',');
            csv->write(name.data(), static_cast<std::streamsize>(name.size()));
          }
          for (int c = 0; c < C; ++c) {
            n = std::snprintf(line, sizeof line, ",%.6g", static_cast<double>(y->outputs[static_cast<std::size_t>(R + c)]));
            csv->write(line, n);
          }
          for (int r = 0; r < R; ++r) {
            n = std::snprintf(line, sizeof line, ",%.7g", static_cast<double>(y->outputs[static_cast<std::size_t>(r)]));
            csv->write(line, n);
          }
          csv->put('\n');
        }
        gap_pending = false;
        ++windows;
      }
    } catch (...) {
      alloc::stop();
      std::signal(SIGINT, previous);
      detail_run::active_source = nullptr;
      throw;
    }
    alloc::stop();
    std::signal(SIGINT, previous);
    detail_run::active_source = nullptr;
  };
  OutputFiles files;
  if (o.out.empty())
    loop(nullptr);
  else
    write_file_atomic_with(files.add(o.out), [&](std::ostream& csv) { loop(&csv); });
  files.commit();

  out << "frames: " << frames << ", windows: " << windows << ", windows restarted after a gap: " << restarts << "\n";
  if (source->problems().empty()) {
    out << "problems: none\n";
  } else {
    out << "problems:";
    for (const auto& [kind, n] : source->problems()) out << " " << kind << " " << n << ";";
    out << "\n";
  }
  const std::size_t timed = latency_us.size();
  const double p50 = quantile_of(latency_us, 0.5), p99 = quantile_of(latency_us, 0.99);
  char buf[256];
  std::snprintf(buf, sizeof buf, "latency of a window (the frame that completes it, pipeline only): p50 %.0f us, p99 %.0f us, "
                "max %.0f us over %zu windows after the first\n", p50, p99, timed ? latency_us.back() : 0.0, timed);
  out << buf;
  out << "allocations after the first window: pipeline " << pipeline_allocations << ", source " << source_allocations
      << (alloc::counts_malloc() ? "" : " (operator new only: a sanitizer owns malloc)") << "\n";
  if (!o.out.empty()) out << "wrote " << o.out << ": " << windows << " windows\n";
  return 0;
}

inline CLI::App* add_run_command(CLI::App& app, RunOptions& o) {
  CLI::App* sub = app.add_subcommand("run", "Encoder and head on a live source (xServer, AnySkin serial, replay): "
                                            "predictions as windows complete, latency and allocations at the end");
  sub->add_option("--model", o.model, "checkpoint of `tjepa pretrain` (or `tjepa convert`)")->required();
  sub->add_option("--head", o.head, "head of `tjepa probe --task ... --save`");
  sub->add_option("--source", o.source,
                  "replay:FILE (a recording at --rate) | ws://HOST[:PORT] (XELA's xServer) | serial:DEVICE[@BAUD] (AnySkin)")
      ->required();
  sub->add_option("--out", o.out, "predictions CSV, one row per window (needs --head)");
  sub->add_option("--encoder", o.encoder, "target | context (the head's)")->capture_default_str();
  sub->add_option("--precision", o.precision, "fp32 | bf16 (the encoder's products)")->capture_default_str();
  sub->add_option("--stride", o.stride, "frames between windows (0: the head's)")->capture_default_str();
  sub->add_option("--frames", o.frames, "stop after this many frames (0: when the source ends)")->capture_default_str();
  sub->add_option("--rate", o.rate, "replay: frames per second (0: back to back); xServer: the sensor's rate, for gaps")
      ->capture_default_str();
  sub->add_option("--reconnects", o.reconnects, "reconnect attempts after a drop (-1: for ever)")->capture_default_str();
  sub->add_option("--backoff", o.backoff, "first wait before reconnecting, s (doubling up to 5 s)")->capture_default_str();
  sub->add_option("--idle-timeout", o.idle_timeout, "xServer: seconds without a message before reconnecting")
      ->capture_default_str();
  add_data_format(sub, o.format);
  sub->add_flag("--force", o.force, "overwrite --out");
  return sub;
}

}  // namespace tjepa::cli
