// A user's program: includes the umbrella header and uses a few pieces.
#include <tjepa/tjepa.hpp>

#include <cstdio>

int main() {
  tjepa::Rng rng(42);
  const tjepa::Edge edges[] = {{0, 1, 1.0}, {1, 2, 1.0}};
  tjepa::TaxelGraph g(3, edges);
  tjepa::ParamSet<float> ps;
  ps.add("w", {2, 3});
  ps.allocate();
  std::printf("tjepa %s: %d nodes, %zu edges, %zu params, u=%.3f\n", tjepa::version_string,
              g.num_nodes(), g.num_edges(), ps.numel(), rng.uniform());
  return g.num_components() == 1 ? 0 : 1;
}
