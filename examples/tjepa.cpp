// The `tjepa` command. `tjepa demo` is the README's main job.
#include <CLI/CLI.hpp>

#include <tjepa/tjepa.hpp>

#include <cstdio>
#include <exception>
#include <vector>

namespace {

// A rows x cols grid skin with 4-neighbour edges of the given pitch.
tjepa::TaxelGraph grid_graph(int rows, int cols, double pitch) {
  std::vector<tjepa::Edge> e;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      const int i = r * cols + c;
      if (c + 1 < cols) e.push_back({i, i + 1, pitch});
      if (r + 1 < rows) e.push_back({i, i + cols, pitch});
    }
  return tjepa::TaxelGraph(rows * cols, e);
}

int demo() {
  const auto g = grid_graph(16, 16, 4.667e-3);
  std::printf("tjepa %s\n", tjepa::version_string);
  std::printf("built-in grid skin: %d taxels, %zu edges, %d part(s), %d component(s)\n",
              g.num_nodes(), g.num_edges(), g.num_parts(), g.num_components());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tjepa: Tactile-JEPA for distributed tactile skins"};
  app.set_version_flag("--version", std::string(tjepa::version_string));
  app.require_subcommand(1);
  auto* demo_cmd = app.add_subcommand("demo", "Run the demo: pre-train on simulated data, then evaluate");
  CLI11_PARSE(app, argc, argv);
  try {
    if (*demo_cmd) return demo();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tjepa: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
