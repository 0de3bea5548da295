// The `tjepa` command: layout / pretrain / probe / embed / convert / demo / eval / run. `tjepa demo` is the
// README's main job. Each subcommand is one file here that registers its options and runs; this
// file only parses the command line and dispatches.
// Any error is one line on stderr ("tjepa: error: ...") and a non-zero exit.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>
#include <iostream>
#include <string>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "convert.hpp"
#include "embed.hpp"
#include "eval.hpp"
#include "layout.hpp"
#include "pretrain.hpp"
#include "probe.hpp"
#include "run.hpp"

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
  CLI::App* layout = add_layout_command(app, lo);
  PretrainOptions po;
  CLI::App* pretrain = add_pretrain_command(app, po);
  ProbeOptions pb;
  CLI::App* probe = add_probe_command(app, pb);
  EmbedOptions eo;
  CLI::App* embed = add_embed_command(app, eo);
  ConvertOptions co;
  CLI::App* convert = add_convert_command(app, co);
  DemoOptions dm;
  CLI::App* demo = add_demo_command(app, dm);
  EvalCommand ev;
  CLI::App* eval = add_eval_command(app, ev);
  RunOptions ro;
  CLI::App* run = add_run_command(app, ro);

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
    if (*demo) return run_demo(dm, std::cout);
    if (*run) return run_live(ro, std::cout);
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
