#pragma once
// Generic grouping for any layout: each part (each connected piece of a part) is cut into
// connected, compact groups of min_size..max_size taxels (e.g. 4-5), by region growing:
//   1. sweep order: breadth-first from a peripheral taxel of the piece (so groups form along a
//      front, like rows of blocks);
//   2. the first unassigned taxel in sweep order seeds a group, which grows by the unassigned
//      neighbour with the most neighbours already in the group (ties: earliest in sweep order), up
//      to the largest size that leaves a remainder still coverable by min..max groups;
//   3. a group left too small (an enclosed pocket) is merged into a neighbouring group with room,
//      takes taxels from neighbouring groups that can spare one without falling apart, is re-cut
//      together with nearby groups (a small exact search), or is dissolved, its taxels pushed
//      into neighbouring groups along chains of groups that pass a taxel on until one has room.
// A sweep whose pockets cannot be repaired is retried from other start taxels (up to 11).
// Deterministic. Throws when a piece has fewer than min_size taxels, when no count of groups of
// min..max taxels sums to its size, or when repair fails (a pathological shape).
#include <algorithm>
#include <bit>
#include <string>
#include <unordered_set>
#include <vector>

#include "tjepa/core/error.hpp"
#include "tjepa/graph/grouping.hpp"
#include "tjepa/graph/skin.hpp"

namespace tjepa {

namespace detail {

// True when n taxels can be cut into groups of lo..hi taxels (n = 0 included).
inline bool coverable(int n, int lo, int hi) {
  if (n == 0) return true;
  const int k = (n + hi - 1) / hi;
  return static_cast<long long>(k) * lo <= n;
}

// Grouping state over one skin: the groups as taxel lists, and each taxel's group. Groups never
// take taxels of another part, even where an edge crosses parts.
struct GrowState {
  const TaxelGraph& g;
  const std::vector<int>& part;
  std::vector<std::vector<int>>& groups;
  std::vector<int>& owner;

  // The group of taxel v if it may join u's group (same part), else -1.
  int peer(int u, int v) const { return part[u] == part[v] ? owner[v] : -1; }

  // Whether group h stays connected without its taxel skip.
  bool connected_without(int h, int skip) const {
    std::vector<int> rest;
    for (int v : groups[h])
      if (v != skip) rest.push_back(v);
    return induces_connected(g, rest);
  }
  void move(int v, int to) {
    auto& from = groups[owner[v]];
    from.erase(std::find(from.begin(), from.end(), v));
    groups[to].push_back(v);
    owner[v] = to;
  }
  // Re-cuts group h together with nearby groups: adds neighbouring groups (breadth-first over group
  // adjacency) until their union, at most 32 taxels, can be partitioned into connected groups of
  // lo..hi taxels, found by a bounded backtracking search. False (nothing changed) if none.
  bool recut(int h, int lo, int hi) {
    std::vector<int> ids{h};
    for (std::size_t next = 0; next < ids.size(); ++next) {
      for (int a : adjacent(ids[next])) {
        if (std::find(ids.begin(), ids.end(), a) != ids.end()) continue;
        ids.push_back(a);
        std::vector<int> u;
        for (int id : ids) u.insert(u.end(), groups[id].begin(), groups[id].end());
        if (u.size() > 32) return false;
        if (!coverable(static_cast<int>(u.size()), lo, hi)) continue;
        std::vector<unsigned> parts;
        if (!partition(u, lo, hi, ids.size(), parts)) continue;
        for (int id : ids) groups[id].clear();
        for (std::size_t k = 0; k < parts.size(); ++k)
          for (std::size_t i = 0; i < u.size(); ++i)
            if (parts[k] >> i & 1u) {
              groups[ids[k]].push_back(u[i]);
              owner[u[i]] = ids[k];
            }
        return true;
      }
    }
    return false;
  }

  // Cuts the taxels u (at most 32) into at most max_sets connected sets of lo..hi taxels, as bit
  // masks over u.
  bool partition(const std::vector<int>& u, int lo, int hi, std::size_t max_sets, std::vector<unsigned>& out) const {
    const int n = static_cast<int>(u.size());
    std::vector<unsigned> adj(n, 0);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        if (i != j && std::find(g.neighbors(u[i]).begin(), g.neighbors(u[i]).end(), u[j]) != g.neighbors(u[i]).end())
          adj[i] |= 1u << j;
    long budget = 200000;
    auto components_coverable = [&](unsigned rest) {
      while (rest) {
        unsigned comp = rest & (~rest + 1), frontier = comp;
        while (frontier) {
          unsigned next = 0;
          for (int i = 0; i < n; ++i)
            if (frontier >> i & 1u) next |= adj[i];
          frontier = next & rest & ~comp;
          comp |= frontier;
        }
        if (!coverable(std::popcount(comp), lo, hi)) return false;
        rest &= ~comp;
      }
      return true;
    };
    // Connected sets holding the lowest taxel of rest, grown one frontier taxel at a time; each of
    // valid size whose remainder's pieces are coverable is tried recursively.
    auto solve = [&](auto&& self, unsigned rest) -> bool {
      if (rest == 0) return true;
      if (out.size() == max_sets) return false;
      const int r = std::countr_zero(rest);
      std::vector<unsigned> stack{1u << r};
      std::unordered_set<unsigned> tried;
      while (!stack.empty()) {
        if (--budget < 0) return false;
        const unsigned s = stack.back();
        stack.pop_back();
        const int size = std::popcount(s);
        if (size >= lo && components_coverable(rest & ~s)) {
          out.push_back(s);
          if (self(self, rest & ~s)) return true;
          out.pop_back();
        }
        if (size == hi) continue;
        unsigned frontier = 0;
        for (int i = 0; i < n; ++i)
          if (s >> i & 1u) frontier |= adj[i];
        frontier &= rest & ~s;
        for (int i = 0; i < n; ++i)
          if (frontier >> i & 1u) {
            const unsigned t = s | 1u << i;
            if (tried.insert(t).second) stack.push_back(t);
          }
      }
      return false;
    };
    out.clear();
    return solve(solve, n == 32 ? ~0u : (1u << n) - 1);
  }


  // Moves taxel u out of group h into a neighbouring group; a group pushed over hi passes one of
  // its taxels on to a further group, breadth-first over groups, until one has room. Every group on
  // the chain stays connected. False (nothing changed) if no chain exists.
  bool push(int u, int h, int hi) {
    struct Step {
      int group, incoming, parent;
    };
    std::vector<Step> steps;
    std::vector<int> visited{h};
    for (int v : g.neighbors(u))
      if (const int a = peer(u, v); a >= 0 && a != h && std::find(visited.begin(), visited.end(), a) == visited.end()) {
        visited.push_back(a);
        steps.push_back({a, u, -1});
      }
    for (std::size_t q = 0; q < steps.size(); ++q) {
      const Step st = steps[q];
      if (static_cast<int>(groups[st.group].size()) < hi) {
        // Apply the chain backwards from its end: each group receives its incoming taxel.
        for (int k = static_cast<int>(q); k >= 0; k = steps[k].parent) move(steps[k].incoming, steps[k].group);
        return true;
      }
      std::vector<int> with = groups[st.group];
      with.push_back(st.incoming);
      for (int x : with) {
        if (x == st.incoming) continue;
        std::vector<int> without;
        for (int y : with)
          if (y != x) without.push_back(y);
        if (!induces_connected(g, without)) continue;
        for (int v : g.neighbors(x)) {
          const int z = peer(x, v);
          if (z < 0 || std::find(visited.begin(), visited.end(), z) != visited.end()) continue;
          visited.push_back(z);
          steps.push_back({z, x, static_cast<int>(q)});
        }
      }
    }
    return false;
  }

  // Groups adjacent to group h, ascending.
  std::vector<int> adjacent(int h) const {
    std::vector<int> out;
    for (int u : groups[h])
      for (int v : g.neighbors(u))
        if (const int a = peer(u, v); a >= 0 && a != h) out.push_back(a);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
  }
};

}  // namespace detail

inline Grouping grow_grouping(const Skin& skin, int min_size, int max_size,
                              GroupWeights weights = GroupWeights::unit) {
  const TaxelLayout& l = skin.layout;
  const TaxelGraph& tg = skin.graph;
  require<ConfigError>(min_size >= 1 && max_size >= min_size, "grow_grouping: n_g range [", min_size, ", ",
                       max_size, "], expected 1 <= min <= max");
  const int n = l.size();
  std::vector<std::vector<int>> groups;
  std::vector<int> owner(n, -1), piece_mark(n, -1), rank(n, -1), cand_links(n, 0);
  detail::GrowState st{tg, l.part, groups, owner};

  // Breadth-first order from s over taxels of s's part; returns the order.
  auto bfs = [&](int s, int mark) {
    std::vector<int> order{s};
    piece_mark[s] = mark;
    for (std::size_t k = 0; k < order.size(); ++k)
      for (int v : tg.neighbors(order[k]))
        if (piece_mark[v] != mark && l.part[v] == l.part[s]) {
          piece_mark[v] = mark;
          order.push_back(v);
        }
    return order;
  };

  int mark = 0;
  for (int s0 = 0; s0 < n; ++s0) {
    if (rank[s0] >= 0) continue;
    // The piece of s0; sweeps start from its last-reached (peripheral) taxel, then from others if
    // a sweep leaves a pocket that cannot be repaired.
    const auto first = bfs(s0, ++mark);
    const int size = static_cast<int>(first.size());
    const std::string where = "part '" + l.part_names[l.part[s0]] + "'" +
                              (size == static_cast<int>(l.taxels_of_part(l.part[s0]).size())
                                   ? std::string()
                                   : " (its connected piece holding taxel " + std::to_string(l.ids[s0]) + ")");
    require<ConfigError>(size >= min_size && detail::coverable(size, min_size, max_size), "grow_grouping: n_g in [",
                         min_size, ", ", max_size, "] cannot cover ", where, " of ", size, " taxels");
    const int first_group = static_cast<int>(groups.size());
    int left_over = -1;  // a taxel of the last unrepaired pocket
    auto attempt = [&](int start) {
      const auto order = bfs(start, ++mark);
      for (std::size_t k = 0; k < order.size(); ++k) rank[order[k]] = static_cast<int>(k);

      // 2. Region growing along the sweep.
      int remaining = size;
      for (int seed : order) {
        if (owner[seed] >= 0) continue;
        int target = remaining;
        if (remaining > max_size) {
          target = min_size;
          for (int s = max_size; s >= min_size; --s)
            if (detail::coverable(remaining - s, min_size, max_size)) {
              target = s;
              break;
            }
        }
        const int h = static_cast<int>(groups.size());
        groups.push_back({seed});
        owner[seed] = h;
        std::vector<int> cand;
        auto add_candidates = [&](int u) {
          for (int v : tg.neighbors(u))
            if (owner[v] < 0 && l.part[v] == l.part[seed]) {
              if (cand_links[v]++ == 0) cand.push_back(v);
            }
        };
        add_candidates(seed);
        while (static_cast<int>(groups[h].size()) < target && !cand.empty()) {
          std::size_t best = 0;
          for (std::size_t k = 1; k < cand.size(); ++k)
            if (cand_links[cand[k]] > cand_links[cand[best]] ||
                (cand_links[cand[k]] == cand_links[cand[best]] && rank[cand[k]] < rank[cand[best]]))
              best = k;
          const int v = cand[best];
          cand.erase(cand.begin() + static_cast<std::ptrdiff_t>(best));
          cand_links[v] = 0;
          groups[h].push_back(v);
          owner[v] = h;
          add_candidates(v);
        }
        for (int v : cand) cand_links[v] = 0;
        // Swallow the pockets the group encloses: pieces of unassigned taxels next to it smaller than
        // min_size, while it has room.
        for (std::size_t k = 0; k < groups[h].size(); ++k)
          for (int v : tg.neighbors(groups[h][k])) {
            if (owner[v] >= 0 || l.part[v] != l.part[seed]) continue;
            std::vector<int> pocket{v};
            ++mark;
            piece_mark[v] = mark;
            for (std::size_t q = 0; q < pocket.size() && static_cast<int>(pocket.size()) < min_size; ++q)
              for (int w : tg.neighbors(pocket[q]))
                if (owner[w] < 0 && piece_mark[w] != mark && l.part[w] == l.part[seed]) {
                  piece_mark[w] = mark;
                  pocket.push_back(w);
                }
            if (static_cast<int>(pocket.size()) < min_size &&
                static_cast<int>(groups[h].size() + pocket.size()) <= max_size &&
                detail::coverable(remaining - static_cast<int>(groups[h].size() + pocket.size()), min_size, max_size))
              for (int w : pocket) {
                groups[h].push_back(w);
                owner[w] = h;
              }
          }
        remaining -= static_cast<int>(groups[h].size());
      }

      // 3. Repair groups below min_size.
      for (int h = first_group; h < static_cast<int>(groups.size()); ++h) {
        while (!groups[h].empty() && static_cast<int>(groups[h].size()) < min_size) {
          bool changed = false;
          for (int a : st.adjacent(h))
            if (groups[a].size() + groups[h].size() <= static_cast<std::size_t>(max_size)) {
              while (!groups[h].empty()) st.move(groups[h].back(), a);
              changed = true;
              break;
            }
          if (changed) break;
          // Take a taxel bordering h from a neighbouring group that can spare it.
          for (std::size_t k = 0; k < groups[h].size() && !changed; ++k)
            for (int v : tg.neighbors(groups[h][k])) {
              const int a = st.peer(groups[h][k], v);
              if (a < 0 || a == h || static_cast<int>(groups[a].size()) <= min_size || !st.connected_without(a, v)) continue;
              st.move(v, h);
              changed = true;
              break;
            }
          if (changed) continue;
          // Re-cut h with its neighbouring groups.
          if (st.recut(h, min_size, max_size)) continue;
          // Dissolve h: push its taxels one at a time into neighbouring groups, passing a taxel on
          // along a chain of groups until one has room.
          bool progress = true;
          while (!groups[h].empty() && progress) {
            progress = false;
            for (std::size_t k = 0; k < groups[h].size() && !progress; ++k) progress = st.push(groups[h][k], h, max_size);
          }
          if (!groups[h].empty()) {
            left_over = groups[h][0];
            for (int v : order) owner[v] = -1;
            groups.resize(first_group);
            return false;
          }
        }
      }
      return true;
    };
    std::vector<int> starts{first.back(), first.front()};
    for (int k = 1; k < 10; ++k) starts.push_back(first[static_cast<std::size_t>(size) * k / 10]);
    bool done = false;
    for (int start : starts)
      if ((done = attempt(start))) break;
    require<DataError>(done, "grow_grouping: could not cut ", where, " into connected groups of ", min_size, "-",
                       max_size, " taxels: a pocket around taxel ", l.ids[left_over],
                       " is left over (the shape may admit no such cut; try a wider n_g range)");
  }
  std::vector<std::vector<int>> kept;
  for (auto& grp : groups)
    if (!grp.empty()) {
      std::sort(grp.begin(), grp.end());
      require<DataError>(static_cast<int>(grp.size()) >= min_size && static_cast<int>(grp.size()) <= max_size,
                         "grow_grouping: a group of ", grp.size(), " taxels around taxel ", l.ids[grp[0]],
                         " is outside [", min_size, ", ", max_size, "]");
      kept.push_back(std::move(grp));
    }
  return make_grouping(skin, kept, weights);
}

}  // namespace tjepa
