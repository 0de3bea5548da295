#pragma once
// tjepa embed: the frozen encoder over a recording's windows, written as embeddings .npy
// [W, N, d].
#include <CLI/CLI.hpp>

#include <cstdint>
#include <ostream>
#include <span>
#include <string>
#include <vector>

#include <tjepa/downstream/embed.hpp>
#include <tjepa/tjepa.hpp>

#include "options.hpp"
#include "output.hpp"
#include "setup.hpp"

namespace tjepa::cli {

struct EmbedOptions {
  std::string checkpoint, data, out;
  std::string encoder = "target";
  DataFormat format;                  // how recordings are read (axes, columns, header, NaN)
  int stride = 0;  // frames between windows (0 = tau)
  bool force = false;
  bool quiet = false;
};

inline int run_embed(const EmbedOptions& o, std::ostream& out) {
  require<ConfigError>(!o.checkpoint.empty() && !o.data.empty() && !o.out.empty(),
                       "--checkpoint, --data and --out are required");
  require<ConfigError>(o.encoder == "target" || o.encoder == "context", "--encoder '", o.encoder,
                       "', expected target or context");
  require<ConfigError>(parse_non_finite(o.format.non_finite) != NonFinite::drop,
                       "embed writes one row per window of the recording; --non-finite drop would shift them: use "
                       "hold, interpolate or zero");
  OutputFiles::check_new(o.out, o.force);
  TrainedModel m = load_trained_model(o.checkpoint);
  JepaModel<float>& model = *m.model;
  Recording rec = in_layout_order(read_recording(o.data, o.format), load_skin(SkinSpec::of(m.config)), o.data);
  require_fits(rec, m);
  m.track(rec);
  const WindowSource src(rec, window_spec(m.config.data.tau, o.format, o.stride), {}, m.pre);
  std::vector<std::int64_t> ids(static_cast<std::size_t>(src.size()));
  for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = static_cast<std::int64_t>(i);
  ProgressLine bar("embed", src.size(), o.quiet);
  const auto emb = embed_windows(o.encoder == "target" ? model.target : model.context, model.tokenizer,
                                 model.encoder, src, ids, 32, [&](std::int64_t d, std::int64_t) { bar.update(d, d, ""); });
  OutputFiles files;
  write_npy(files.add(o.out), std::span<const float>(emb.data(), emb.size()),
            {src.size(), model.num_tokens(), model.dim()});
  files.commit();
  out << "wrote " << o.out << ": [" << src.size() << ", " << model.num_tokens() << ", " << model.dim()
      << "] embeddings of windows of " << m.config.data.tau << " frames\n";
  return 0;
}

// The subcommand and its options, which fill o (it outlives the parse).
inline CLI::App* add_embed_command(CLI::App& app, EmbedOptions& o) {
  CLI::App* sub = app.add_subcommand("embed", "Frozen encoder over a recording's windows -> embeddings .npy [W, N, d]");
  sub->add_option("--checkpoint", o.checkpoint, "checkpoint of `tjepa pretrain`")->required();
  sub->add_option("--data", o.data, "recording (.npy [T, N, m] or CSV)")->required();
  sub->add_option("--out", o.out, "output .npy")->required();
  sub->add_option("--encoder", o.encoder, "target | context")->capture_default_str();
  sub->add_option("--stride", o.stride, "frames between windows (0: tau)")->capture_default_str();
  add_data_format(sub, o.format);
  sub->add_flag("--force", o.force, "overwrite --out");
  sub->add_flag("--quiet", o.quiet, "no progress line");
  return sub;
}

}  // namespace tjepa::cli
