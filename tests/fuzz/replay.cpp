// Replays fuzz inputs through the targets of targets.hpp without libFuzzer, so every build's tests
// run each target's corpus (and a crash the fuzzer found can be rerun under any compiler):
//   tjepa_fuzz_replay [-v] <target> <file or directory>...   (-v: print what each read threw)
//   tjepa_fuzz_replay --write-corpus <dir>     writes the seed corpora with tjepa's own writers
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <tjepa/core/atomic_write.hpp>
#include <tjepa/train/reference_checkpoint.hpp>
#include <tjepa/train/jepa_objective.hpp>

#include "targets.hpp"

namespace fs = std::filesystem;

namespace {

tjepa::Skin grid4() {
  tjepa::layouts::GridSkinOptions o;
  o.rows = o.cols = 4;
  return tjepa::layouts::grid_skin(o);
}

void write_corpus(const fs::path& root) {
  auto dir = [&](const char* name) {
    fs::create_directories(root / name);
    return root / name;
  };
  // safetensors: tensors of two dtypes, with metadata.
  {
    tjepa::SafetensorsFile f;
    f.add<float>("a.weight", std::vector<float>{1.f, -2.f, 3.5f, 0.f, 1e-3f, 7.f}, {2, 3});
    f.add<double>("b", std::vector<double>{0.25, -1.0}, {2});
    f.metadata["note"] = "seed";
    tjepa::save_safetensors(dir("safetensors") / "two_tensors.safetensors", f);
  }
  // checkpoint: a tiny model on a 4 x 4 grid with its run config, as a Trainer writes it.
  {
    const tjepa::Skin skin = grid4();
    tjepa::TrainConfig c;
    c.model.dim = 8, c.model.depth = 1, c.model.heads = 2, c.model.predictor_depth = 1, c.data.tau = 2, c.masks.min_context_tokens = 4;
    const auto model = tjepa::make_jepa_model<float>(c, skin.graph, 3, 0);
    tjepa::CheckpointState st;
    st.step = 3;
    st.config = tjepa::run_metadata(c, model->config);
    const auto parts = model->parts();
    tjepa::save_checkpoint<float>(dir("checkpoint") / "tiny.safetensors", parts, nullptr, st);
  }
  // npy: a recording [frames, taxels, axes] in float32 and a 1-D float64 array.
  {
    std::vector<float> v(4 * 3 * 3);
    for (std::size_t i = 0; i < v.size(); ++i) v[i] = 0.5f * static_cast<float>(i) - 3.f;
    tjepa::write_npy<float>(dir("npy") / "recording.npy", v, {4, 3, 3});
    tjepa::write_npy<double>(dir("npy") / "vector.npy", std::vector<double>{1.0, -2.5, 1e-300}, {3});
  }
  // text recording: a header row and 3 frames of 2 taxels x 3 axes.
  tjepa::write_file_atomic(dir("text_recording") / "frames.csv",
                           "t0x,t0y,t0z,t1x,t1y,t1z\n0.1,0.2,0.3,1,2,3\n-1,-2,-3,4.5,5.5,6.5\n0,0,0,1e3,nan,2\n");
  tjepa::write_file_atomic(dir("text_recording") / "frames_no_header.txt", "0.5 1 2 3 4 5\n6 7 8 9 10 11\n");
  tjepa::write_file_atomic(dir("text_recording") / "icub_slices.txt", "-10000\n1 2 3 \n4 5\n6 7 8\n10 20 30 \n40 50\n60 70 80\n");
  tjepa::write_file_atomic(dir("trial_table") / "table.csv",
                           "# trials\nlabel,file,split,group\nbook,\"a,1.csv\",train,s1\n\"x\"\"y\",b.csv,test,\n");
  // layouts and edges, by tjepa's CSV writers.
  {
    const tjepa::Skin grid = grid4();
    tjepa::write_layout_csv(dir("layout_csv") / "grid.csv", grid.layout);
    tjepa::write_layout_csv(dir("layout_csv") / "two_part.csv", tjepa::layouts::two_part_skin().layout);
    tjepa::write_edges_csv(dir("edges_csv") / "grid_edges.csv", grid.layout, grid.graph);
  }
  tjepa::write_file_atomic(dir("run_config") / "defaults.json", tjepa::TrainConfig{}.to_json().dump(2));
  // reference_checkpoint: a 6-taxel reference-code state dict (padding 2, taxel types, normalization).
  {
    tjepa::JepaConfig c = tjepa::JepaConfig::reference(6, 15, 3);  // τ = 5
    c.encoder.dim = c.predictor.in_dim = c.predictor.dim = 8;
    c.encoder.depth = c.predictor.depth = 1;
    c.encoder.heads = c.predictor.heads = 2;
    c.temporal_padding = 2;
    c.encoder.token_types = 1;
    c.encoder.token_type.assign(6, 0);
    const tjepa::JepaModel<float> m(c, 0);
    tjepa::ReferenceFacts facts;
    facts.version_marker = -1;
    facts.mean = {0.f, 1.f, 2.f};
    facts.std = {1.f, 2.f, 3.f};
    tjepa::save_safetensors(dir("reference_checkpoint") / "tiny.safetensors", tjepa::reference_state(m, facts, {}));
  }
}

std::vector<char> read_all(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::vector<char>((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 3 && std::strcmp(argv[1], "--write-corpus") == 0) {
    write_corpus(argv[2]);
    return 0;
  }
  if (argc >= 2 && std::strcmp(argv[1], "-v") == 0) {
    tjepa::fuzz::verbose = true;
    --argc;
    ++argv;
  }
  const tjepa::fuzz::Target* target = nullptr;
  if (argc >= 3)
    for (const auto& t : tjepa::fuzz::targets)
      if (std::strcmp(argv[1], t.name) == 0) target = &t;
  if (target == nullptr) {
    std::fprintf(stderr, "usage: tjepa_fuzz_replay <target> <file or directory>...\n"
                         "       tjepa_fuzz_replay --write-corpus <dir>\ntargets:");
    for (const auto& t : tjepa::fuzz::targets) std::fprintf(stderr, " %s", t.name);
    std::fprintf(stderr, "\n");
    return 2;
  }
  std::vector<fs::path> files;
  for (int i = 2; i < argc; ++i) {
    if (fs::is_directory(argv[i])) {
      for (const auto& e : fs::directory_iterator(argv[i]))
        if (e.is_regular_file()) files.push_back(e.path());
    } else {
      files.emplace_back(argv[i]);
    }
  }
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    const std::vector<char> bytes = read_all(f);
    target->run(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
  }
  std::error_code ec;
  for (const char* s : {".safetensors", ".npy", ".csv", ".nodes.csv", ".edges.csv", ".json"})
    fs::remove(tjepa::fuzz::scratch_file(s), ec);
  std::printf("%s: %zu input(s) replayed, no finding\n", target->name, files.size());
  return files.empty() ? 1 : 0;
}
