#pragma once
// tjepa convert: the reference code's checkpoints (E-Kovtun/tactile, as a safetensors state dict)
// into a tjepa checkpoint that `probe` and `embed` read, and a tjepa checkpoint back into the
// reference's state dict. The direction follows the input: a file with tjepa's checkpoint metadata
// goes to the reference, any other safetensors file comes from it. A PyTorch .ckpt / .pt goes
// through tools/reference/torch_checkpoint.py first (torch is not a dependency of tjepa).
//
// Reference → tjepa: the model from the tensors' shapes (train/reference_checkpoint.hpp), the layout
// and its recording order (default: the Allegro hand in the reference's order for 368 taxels), the
// in-model normalization as the checkpoint's preprocessing. What tjepa cannot represent is refused
// by name. Round trip reference → tjepa → reference gives the same tensors, bit for bit.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <filesystem>
#include <ostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include <tjepa/train/reference_checkpoint.hpp>
#include <tjepa/train/jepa_objective.hpp>
#include <tjepa/train/trained_model.hpp>

#include "output.hpp"
#include "setup.hpp"

namespace tjepa::cli {

struct ConvertOptions {
  std::string in, out;
  int heads = 0;             // 0: the reference's config (metadata) or its model sizes
  int padding = -1;          // temporal padding; -1: from the file's _temporal_patch_version
  std::string layout;        // the skin ("": allegro for 368 taxels)
  std::string edges, columns, bridges = "connect";
  std::string order;         // the recordings' taxel order ("": reference for the Allegro hand)
  std::string taxel_types;   // comma list in the reference's token order ("": the Xela hand's)
  bool force = false;
};

namespace detail_convert {
inline std::vector<int> int_list(const std::string& s, const char* what) {
  std::vector<int> v;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      std::size_t used = 0;
      v.push_back(std::stoi(item, &used));
      require<ConfigError>(used == item.size(), "");
    } catch (const std::exception&) {
      fail<ConfigError>(what, ": '", item, "' is not an integer");
    }
  }
  return v;
}

// The recordings' order of the skin as the reference's token order of each tjepa token.
inline std::vector<int> token_order(const Skin& skin) {
  return skin.layout.has_columns() ? skin.layout.column : std::vector<int>{};
}
}  // namespace detail_convert

inline int run_convert_to_reference(const ConvertOptions& o, std::ostream& out) {
  TrainedModel m = load_trained_model(o.in);
  const JepaModel<float>& model = *m.model;
  const Skin skin = load_skin(SkinSpec::of(m.config));
  ReferenceOptions opt;
  opt.order = detail_convert::token_order(skin);
  const SafetensorsFile in = load_safetensors(o.in);
  ReferenceFacts facts;
  std::vector<std::string> notes;
  if (const auto it = in.metadata.find("reference.facts"); it != in.metadata.end()) {
    facts = ReferenceFacts::from_json(json_parse<FileError>(it->second, o.in + ": metadata 'reference.facts'"),
                                      o.in + ": metadata 'reference.facts'");
  } else {
    facts.version_marker = model.config.temporal_padding == 0 ? 1 : 0;
    const int axes = model.config.axes;
    const PreprocessConfig& pc = m.pre.config();
    require<ConfigError>(pc.scaling != Scaling::part_max, o.in,
                         ": per-part maximum scaling has no counterpart in the reference's model (xela_mean / xela_std)");
    if (pc.scaling == Scaling::per_axis) {
      facts.mean = m.pre.mean();
      facts.std = m.pre.std();
    } else if (pc.scaling == Scaling::scalar) {
      facts.mean.assign(static_cast<std::size_t>(axes), m.pre.mean().at(0));
      facts.std.assign(static_cast<std::size_t>(axes), m.pre.std().at(0));
    } else {
      facts.mean.assign(static_cast<std::size_t>(axes), 0.0f);
      facts.std.assign(static_cast<std::size_t>(axes), 1.0f);
    }
    if (pc.subtract_baseline || pc.clip_dropouts)
      notes.push_back("the run subtracted each taxel's baseline and/or cleared drop-outs before the model: "
                      "the reference's dataset does the same before its model (subtract_baseline), not the model");
    if (m.drift) notes.push_back("the run tracked drift; the reference has no drift tracking");
  }
  SafetensorsFile f = reference_state(model, facts, opt);
  const auto& c = model.config;
  const int tau = c.in_dim / c.axes;
  f.metadata["format"] = "tactile_ssl.state_dict";
  f.metadata["global_step"] = std::to_string(m.step);
  f.metadata["reference.config"] = nlohmann::json{{"in_dim", c.encoder.num_tokens},
                                                  {"in_chans", c.axes},
                                                  {"sequence_length", tau},
                                                  {"time_chunk_size", tau},
                                                  {"temporal_patch_padding", c.temporal_padding},
                                                  {"embed_dim", c.encoder.dim},
                                                  {"depth", c.encoder.depth},
                                                  {"num_heads", c.encoder.heads},
                                                  {"use_taxel_type_embedding", c.encoder.token_types > 0}}
                                       .dump();
  OutputFiles files;
  save_safetensors(files.add(o.out), f);
  files.commit();
  out << "wrote " << o.out << ": the reference's XelaJEPAModule state dict (" << f.size() << " tensors; "
      << c.encoder.num_tokens << " taxels, d " << c.encoder.dim << ", depth " << c.encoder.depth << ", heads "
      << c.encoder.heads << ", predictor depth " << c.predictor.depth << ", temporal padding " << c.temporal_padding
      << ")\n";
  for (const auto& n : notes) out << "note: " << n << '\n';
  out << "for PyTorch: python3 tools/reference/torch_checkpoint.py to-torch " << o.out << " model.ckpt\n";
  return 0;
}

inline int run_convert_from_reference(const ConvertOptions& o, const SafetensorsFile& f, std::ostream& out) {
  ReferenceOptions opt;
  opt.heads = o.heads;
  opt.temporal_padding = o.padding;
  if (!o.taxel_types.empty()) opt.token_types = detail_convert::int_list(o.taxel_types, "--taxel-types");
  if (const auto it = f.metadata.find("reference.config"); it != f.metadata.end() && opt.heads == 0) {
    const auto rc = json_parse<FileError>(it->second, o.in + ": metadata 'reference.config'");
    if (rc.contains("num_heads") && rc["num_heads"].is_number_integer()) opt.heads = rc["num_heads"].get<int>();
  }
  // The run config's explicit padding wins over the default of a file without the version marker,
  // as in the reference (an explicit --padding wins over both).
  std::string padding_from;
  if (const auto it = f.metadata.find("reference.config"); it != f.metadata.end() && opt.temporal_padding < 0) {
    const auto rc = json_parse<FileError>(it->second, o.in + ": metadata 'reference.config'");
    if (rc.contains("temporal_patch_padding")) {
      require<FileError>(rc["temporal_patch_padding"].is_number_integer(), o.in,
                         ": metadata 'reference.config': temporal_patch_padding is not an integer");
      opt.temporal_padding = rc["temporal_patch_padding"].get<int>();
      padding_from = " (the run config's temporal_patch_padding)";
    }
  }
  const Tensor& pos = detail::reference_tensor(f, "context_encoder.pos_embed");
  const int tokens = pos.shape.size() == 3 ? static_cast<int>(pos.shape[1]) : 0;
  SkinSpec spec;
  spec.layout = o.layout.empty() ? "allegro" : o.layout;
  spec.edges = o.edges;
  spec.columns = o.columns;
  spec.bridges = o.bridges;
  spec.order = o.order.empty() && spec.layout == "allegro" ? "reference" : o.order;
  require<ConfigError>(!o.layout.empty() || tokens == layouts::allegro::kTaxels, o.in, ": a model of ", tokens,
                       " taxels: give its layout (--layout, and --order for the recordings' taxel order)");
  std::ostringstream warnings;
  const Skin skin = load_skin(spec, &warnings);
  out << warnings.str();
  require<ConfigError>(skin.size() == tokens, o.in, ": a model of ", tokens, " taxels, layout '", spec.layout,
                       "' has ", skin.size());
  opt.order = detail_convert::token_order(skin);
  ReferenceFacts facts;
  const JepaConfig c = reference_model_config(f, opt, &facts);
  JepaModel<float> model(c, 0);
  load_reference_state(f, model, opt);

  TrainConfig tc = TrainConfig::reference(1);
  tc.data.layout = spec.layout;
  tc.data.layout_edges = spec.edges;
  tc.data.layout_columns = spec.columns;
  tc.data.bridges = spec.bridges;
  tc.data.taxel_order = spec.order;
  tc.data.tau = c.in_dim / c.axes;
  tc.model.dim = c.encoder.dim;
  tc.model.depth = c.encoder.depth;
  tc.model.heads = c.encoder.heads;
  tc.model.predictor_depth = c.predictor.depth;
  tc.validate();
  const Preprocessor pre = facts.mean.empty() ? Preprocessor{} : Preprocessor::with_statistics(facts.mean, facts.std);
  CheckpointState st = data_state(pre);
  st.config = run_metadata(tc, c);
  st.config["version"] = checkpoint_metadata_version;
  st.metadata["reference.facts"] = facts.to_json().dump();
  st.metadata["reference.source"] = o.in;
  if (const auto it = f.metadata.find("global_step"); it != f.metadata.end()) {
    try {
      st.step = std::stoll(it->second);
    } catch (const std::exception&) {
      fail<FileError>(o.in, ": metadata 'global_step' = '", it->second, "', expected an integer");
    }
  }
  OutputFiles files;
  const auto parts = model.parts();
  save_checkpoint(files.add(o.out), std::span<const PrefixedParams<float>>(parts), static_cast<const AdamW<float>*>(nullptr), st);
  files.commit();
  out << "wrote " << o.out << ": " << c.encoder.num_tokens << " taxels (layout " << spec.layout
      << (spec.order.empty() ? "" : ", order " + spec.order) << "), windows of " << tc.data.tau << " frames x " << c.axes
      << " axes, d " << c.encoder.dim << ", depth " << c.encoder.depth << ", heads " << c.encoder.heads
      << ", predictor depth " << c.predictor.depth << ", temporal padding " << c.temporal_padding << padding_from
      << (c.encoder.token_types > 0 ? ", taxel types " + std::to_string(c.encoder.token_types) : std::string())
      << (facts.mean.empty() ? std::string(", no in-model normalization") : ", its normalization as preprocessing")
      << "\n"
      << "note: the reference's dataset subtracts each taxel's baseline before the model; give embed and probe "
         "baseline-subtracted recordings\n"
      << "note: no optimizer state: the checkpoint is for probe and embed (and a new pre-training), not a resume\n";
  return 0;
}

inline int run_convert(const ConvertOptions& o, std::ostream& out) {
  require<ConfigError>(!o.in.empty() && !o.out.empty(), "convert: an input file and --out are required");
  const std::string ext = std::filesystem::path(o.in).extension().string();
  require<ConfigError>(ext != ".ckpt" && ext != ".pt" && ext != ".pth", o.in,
                       " is a PyTorch file; tjepa reads safetensors: python3 tools/reference/torch_checkpoint.py "
                       "to-safetensors ", o.in, " ref.safetensors [--config .hydra/config.yaml], then convert that");
  require_input_file(o.in, "input");
  OutputFiles::check_new(o.out, o.force);
  const SafetensorsFile f = load_safetensors(o.in);
  const auto it = f.metadata.find("format");
  if (it != f.metadata.end() && it->second == checkpoint_format) return run_convert_to_reference(o, out);
  return run_convert_from_reference(o, f, out);
}

// The subcommand and its options, which fill o (it outlives the parse).
inline CLI::App* add_convert_command(CLI::App& app, ConvertOptions& o) {
  CLI::App* sub = app.add_subcommand(
      "convert", "The reference code's checkpoint (safetensors state dict) to a tjepa checkpoint, or a tjepa "
      "checkpoint back to the reference's state dict");
  sub->add_option("input", o.in, "reference state dict (.safetensors; a .ckpt via "
                                      "tools/reference/torch_checkpoint.py) or tjepa checkpoint")->required();
  sub->add_option("--out", o.out, "output .safetensors")->required();
  sub->add_option("--heads", o.heads, "attention heads (default: the file's config or the reference's model sizes)");
  sub->add_option("--padding", o.padding, "the tokenizer's temporal padding, 0 or 2 (default: the file's marker)");
  sub->add_option("--layout", o.layout, "the skin: built-in layout or layout CSV (default: allegro for 368 taxels)");
  sub->add_option("--edges", o.edges, "edges CSV of a layout CSV");
  sub->add_option("--layout-columns", o.columns, "the layout CSV's column names, e.g. x=visual_x,y=visual_y");
  sub->add_option("--bridges", o.bridges, "inferred graphs: connect | near | none")->capture_default_str();
  sub->add_option("--order", o.order, "the recordings' (= the reference model's) taxel order: reference | "
                                           "xserver | id,column CSV (default: reference for allegro)");
  sub->add_option("--taxel-types", o.taxel_types, "type of each token in the reference's order, e.g. 2,2,0,1 "
                                                       "(default: the Xela hand's 4x4 / 4x6 / curved pads)");
  sub->add_flag("--force", o.force, "overwrite --out");
  return sub;
}

}  // namespace tjepa::cli
