// The `tjepa` command: layout / pretrain / probe / embed / convert / eval / demo. `tjepa demo` is the README's
// main job. The subcommands live in cli/commands.hpp; this file only parses the command line.
// Any error is one line on stderr ("tjepa: error: ...") and a non-zero exit.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>
#include <iostream>
#include <string>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "cli/commands.hpp"
#include "cli/convert.hpp"
#include "cli/eval.hpp"
#include "cli/parse.hpp"

#ifdef TJEPA_WITH_MPI
#include <tjepa/dist/mpi.hpp>
#endif


int main(int argc, char** argv) {
  using namespace tjepa::cli;
#ifdef TJEPA_WITH_MPI
  // Under mpirun every rank runs this program; `tjepa pretrain` shares each batch among them.
  tjepa::dist::MpiSession mpi(&argc, &argv);
#endif
  CLI::App app{"tjepa: Tactile-JEPA for distributed tactile skins"};
  app.set_version_flag("--version", std::string(tjepa::version_string));
  app.require_subcommand(1);
  int threads = 0;
  app.add_option("--threads", threads, "OpenMP threads (0: all cores); before or after the subcommand");
  app.fallthrough();

  LayoutOptions lo;
  auto* layout = app.add_subcommand("layout", "Draw a layout, its graph, groups or sampled masks; print a summary");
  layout->add_option("layout", lo.layout, "built-in layout (allegro, grid, two-part) or layout CSV")->capture_default_str();
  layout->add_option("--svg", lo.svg, "write an SVG drawing here");
  layout->add_option("--draw", lo.draw, "graph | groups | parts | masks")->capture_default_str();
  layout->add_option("--mask-seed", lo.seed, "seed of the drawn masks");
  layout->add_flag("--json", lo.json, "machine-readable summary on stdout");
  layout->add_flag("--force", lo.force, "overwrite the SVG / exported files");
  layout->add_option("--edges", lo.edges, "edges CSV of a layout CSV (src,dst[,weight]); default: inferred");
  layout->add_option("--layout-columns", lo.columns, "the layout CSV's column names, e.g. x=visual_x,y=visual_y");
  layout->add_option("--bridges", lo.bridges, "inferred graphs: connect | near | none")->capture_default_str();
  layout->add_option("--order", lo.order, "recordings' taxel order: xserver | reference (allegro) | id,column CSV");
  layout->add_option("--export", lo.export_csv, "write the layout as CSV (order included), its edges to *.edges.csv");
  layout->add_flag("--strict", lo.strict, "warnings about the graph are errors");

  PretrainOptions po;
  auto* pretrain = app.add_subcommand("pretrain", "Pre-train Tactile-JEPA: checkpoint, CSV log, loss-curve SVG");
  pretrain->add_option("--config", po.config, "JSON run configuration (keys as in the checkpoint's config.run)");
  add_run_overrides(pretrain, po.overrides);
  pretrain->add_option("--data", po.data, "recordings (.npy [T, N, m] or CSV); default: simulated data");
  pretrain->add_option("--baseline", po.baseline, "no-contact recording (preprocessing xela or baseline)");
  pretrain->add_option("--preprocess", po.preprocess, "auto | xela | baseline | standardize | none")->capture_default_str();
  add_data_format(pretrain, po.format);
  pretrain->add_option("--simulate", po.simulate_frames, "frames of simulated data")->capture_default_str();
  pretrain->add_option("--simulate-contacts", po.simulate_contacts, "indenters touching at once in simulated data")
      ->capture_default_str();
  pretrain->add_option("--out", po.out, "output directory (default: runs/pretrain; a resumed run's own folder)");
  pretrain->add_flag("--force", po.force, "overwrite an existing checkpoint");
  pretrain->add_flag("--quiet", po.quiet, "no progress line");
  pretrain->add_option("--resume", po.resume, "continue the run of this checkpoint (same data and config)");
  pretrain->add_option("--stop-after", po.stop_after, "stop and save after this many steps of the schedule");
  pretrain->add_flag("--strict", po.strict, "warnings about the layout's graph are errors");

  ProbeOptions pb;
  auto* probe = app.add_subcommand("probe", "Train and evaluate probes on a frozen checkpoint: force and indenter, or your own labels (--task)");
  probe->add_option("--checkpoint", pb.checkpoint, "checkpoint of `tjepa pretrain`")->required();
  probe->add_option("--encoder", pb.encoder, "target | context")->capture_default_str();
  probe->add_option("--train-data", pb.train_data, "labelled training recording (default: simulated)");
  probe->add_option("--train-labels", pb.train_labels,
                    "labels per frame: [T, 4] .npy (force u, v, normal, indenter class or -1), or with --task your own");
  probe->add_option("--task", pb.task, "your own labels: regression (any number of columns) | classification (class ids)");
  probe->add_option("--label-columns", pb.label_columns, "text label files: the label columns, e.g. 1:3");
  probe->add_option("--data", pb.data, "with --task: one recording, split in time (--test-fraction)");
  probe->add_option("--labels", pb.labels, "with --task and --data: its labels, one row per frame");
  probe->add_option("--test-fraction", pb.test_fraction, "with --data: the last fraction of frames held out")
      ->capture_default_str();
  probe->add_option("--test-data", pb.test_data, "held-out recording");
  probe->add_option("--test-labels", pb.test_labels, "held-out labels");
  probe->add_option("--simulate-seed", pb.simulate_seed, "seed of the simulated labelled data")->capture_default_str();
  probe->add_option("--simulate-train-frames", pb.simulate_train_frames, "simulated labelled frames to train on")
      ->capture_default_str()->check(CLI::Range(1, 1 << 30));
  probe->add_option("--simulate-test-frames", pb.simulate_test_frames, "simulated held-out frames")
      ->capture_default_str()->check(CLI::Range(1, 1 << 30));
  probe->add_option("--min-contact", pb.min_contact,
                    "frames in contact for a window to count (default: 5 with simulated labels, off with --task)");
  probe->add_option("--contact-threshold", pb.contact_threshold,
                    "--task: a frame is in contact when a taxel's preprocessed reading exceeds this norm")
      ->capture_default_str();
  probe->add_option("--max-windows", pb.max_windows, "labelled windows per split (0: all)")->capture_default_str();
  probe->add_option("--epochs", pb.probe.max_epochs, "probe epoch limit (early stopping)")->capture_default_str();
  probe->add_option("--patience", pb.probe.patience, "epochs without a better validation loss before stopping")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  probe->add_option("--batch", pb.probe.batch, "probe batch")->capture_default_str();
  probe->add_option("--repeats", pb.repeats, "probes with seeds seed, seed+1, ... averaged (mean ± sd)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  probe->add_option("--lr", pb.probe.lr, "probe learning rate")->capture_default_str();
  add_data_format(probe, pb.format);
  probe->add_option("--out", pb.out, "write the results as JSON here");
  probe->add_flag("--force", pb.force, "overwrite --out");
  probe->add_flag("--quiet", pb.quiet, "no progress line");
  probe->add_flag("--center-tokens", pb.center_tokens,
                  "the probe reads each token's embedding minus its training mean (center_token_embeddings)");

  EmbedOptions eo;
  auto* embed = app.add_subcommand("embed", "Frozen encoder over a recording's windows -> embeddings .npy [W, N, d]");
  embed->add_option("--checkpoint", eo.checkpoint, "checkpoint of `tjepa pretrain`")->required();
  embed->add_option("--data", eo.data, "recording (.npy [T, N, m] or CSV)")->required();
  embed->add_option("--out", eo.out, "output .npy")->required();
  embed->add_option("--encoder", eo.encoder, "target | context")->capture_default_str();
  embed->add_option("--stride", eo.stride, "frames between windows (0: tau)")->capture_default_str();
  add_data_format(embed, eo.format);
  embed->add_flag("--force", eo.force, "overwrite --out");
  embed->add_flag("--quiet", eo.quiet, "no progress line");

  ConvertOptions co;
  auto* convert = app.add_subcommand(
      "convert", "The reference code's checkpoint (safetensors state dict) to a tjepa checkpoint, or a tjepa "
      "checkpoint back to the reference's state dict");
  convert->add_option("input", co.in, "reference state dict (.safetensors; a .ckpt via "
                                      "tools/reference/torch_checkpoint.py) or tjepa checkpoint")->required();
  convert->add_option("--out", co.out, "output .safetensors")->required();
  convert->add_option("--heads", co.heads, "attention heads (default: the file's config or the reference's model sizes)");
  convert->add_option("--padding", co.padding, "the tokenizer's temporal padding, 0 or 2 (default: the file's marker)");
  convert->add_option("--layout", co.layout, "the skin: built-in layout or layout CSV (default: allegro for 368 taxels)");
  convert->add_option("--edges", co.edges, "edges CSV of a layout CSV");
  convert->add_option("--layout-columns", co.columns, "the layout CSV's column names, e.g. x=visual_x,y=visual_y");
  convert->add_option("--bridges", co.bridges, "inferred graphs: connect | near | none")->capture_default_str();
  convert->add_option("--order", co.order, "the recordings' (= the reference model's) taxel order: reference | "
                                           "xserver | id,column CSV (default: reference for allegro)");
  convert->add_option("--taxel-types", co.taxel_types, "type of each token in the reference's order, e.g. 2,2,0,1 "
                                                       "(default: the Xela hand's 4x4 / 4x6 / curved pads)");
  convert->add_flag("--force", co.force, "overwrite --out");

  std::uint64_t demo_seed = 0;
  std::string demo_out = "runs/demo";
  bool demo_quiet = false;
  nlohmann::json demo_overrides = nlohmann::json::object();
  auto* demo = app.add_subcommand(
      "demo", "tjepa eval cut to one seed and one head per task: pre-train on the simulated grasping hand, then "
      "object / force / pose against baselines");
  demo->add_option("--seed", demo_seed, "seed of everything (data, init, masks, heads)")->capture_default_str();
  demo->add_option("--out", demo_out, "output directory")->capture_default_str();
  run_override<int>(demo, "--steps", "steps", demo_overrides, "pre-training steps");
  run_override<int>(demo, "--warmup", "warmup_steps", demo_overrides, "pre-training warm-up steps");
  demo->add_flag("--quiet", demo_quiet, "no progress lines");

  EvalCommand ev;
  auto* eval = add_eval_command(app, ev);

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(stderr, "tjepa: error: %s (see tjepa --help)\n", e.what());
    return 2;
  }
#ifdef _OPENMP
  if (threads > 0) omp_set_num_threads(threads);
#endif
  const auto dispatch = [&]() -> int {
#ifdef TJEPA_WITH_MPI
    if (mpi.size() > 1) {
      tjepa::require<tjepa::ConfigError>(pretrain->parsed(), "only `tjepa pretrain` runs on more than one MPI rank (this is "
                                         "rank ", mpi.rank(), " of ", mpi.size(), ")");
      po.parallel = tjepa::dist::mpi_data_parallel<float>(mpi.comm());
    }
#endif
    if (*layout) return run_layout(lo, std::cout);
    if (*pretrain) return run_pretrain(po, std::cout);
    if (*probe) return run_probe(pb, std::cout);
    if (*embed) return run_embed(eo, std::cout);
    if (*convert) return run_convert(co, std::cout);
    if (*eval) return run_eval(ev.resolve(argc, argv, &std::cout), std::cout);
    if (*demo) {
      EvalOptions dm = demo_eval_options(demo_seed);
      dm.out = demo_out;
      dm.quiet = demo_quiet;
      dm.eval.train.update(demo_overrides, "command line");
      fit_default_warmup(dm.eval.train, demo_overrides, std::cout);
      return run_eval(dm, std::cout);
    }
    return 0;
  };
#ifdef TJEPA_WITH_MPI
  if (mpi.size() > 1) return mpi.run_or_abort(dispatch);  // one rank's error stops them all
#endif
  try {
    return dispatch();
  } catch (const std::exception& e) {
    std::fflush(stdout);
    std::fprintf(stderr, "%stjepa: error: %s\n", ::isatty(::fileno(stderr)) ? "\r\033[K" : "", e.what());
    return 1;
  }
  return 0;
}
