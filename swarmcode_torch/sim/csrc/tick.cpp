// The fused CPU tick: swarmcode_torch/sim/step.py's `step`, one environment at a time, all of
// a rollout's ticks in one call, environments in parallel (ATen's thread pool, OpenMP).
//
// The Python tick (step.py, sense.py, contacts.py) is the reference: every line below follows it
// in the same order of float operations where that is cheap, so that results agree to float
// rounding (the summation order of the contact solver's sums and of `norm` differ; see
// benchmarks/README.md for the measured tolerance). What is done differently, for speed:
//   * sensing visits only the grip points a robot is compatible with (its effector's), built
//     once per call from `compat`, not all H;
//   * robot-robot contacts sum only the pairs that overlap (the others add exact zeros), found
//     by sweep and prune along x (every overlapping pair: no per-cell capacity as in the
//     reference's broad phase from broad_phase_min_robots); obstacles likewise;
//   * a robot runs all ticks of the call in cache, one environment after the other.
#include <torch/types.h>
#include <torch/python.h>
#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace {

constexpr int S_SUCCESS = 0, S_FAILURE = 1, S_RUNNING = 2;
constexpr int ACT_MOVE_TO_PACK = 6, ACT_MOVE_TO_BASE = 7, ACT_RANDOM_WALK = 8, ACT_PICK_UP = 9,
              ACT_DROP = 10, ACT_MOVE_TO_RANDOM_PACK = 11, NOP = 13;
constexpr int FIRED_SHIFT = 4;
constexpr int64_t GROUND = 0, HELD = 1, DELIVERED = 2;
constexpr float INF = 1e9f;
constexpr uint64_t HASH_B = 0xC2B2AE3Dull, MASK32 = 0xFFFFFFFFull;

struct Params {
  float arena, base_radius, dt, drag, v_cap, kp, kv, reach, near_, idle_power, stuck_slow,
      anchor_mass, rest_speed, cell_size, wp_lo, wp_span, base;
  int64_t stuck_ticks, waypoint_period, collision_iters, grid;
};

inline float norm2(float x, float y) { return std::sqrt(x * x + y * y); }

inline float waypoint_u(int64_t key, int64_t t) {
  uint64_t x = (static_cast<uint64_t>(key) + static_cast<uint64_t>(t) * HASH_B) & MASK32;
  x = x ^ (x >> 16);
  x = (x * 0x7FEB352Dull) & MASK32;
  x = x ^ (x >> 15);
  x = (x * 0x846CA68Bull) & MASK32;
  x = x ^ (x >> 16);
  return static_cast<float>(static_cast<int64_t>(x)) * (1.0f / 4294967296.0f);
}

// _cap(v, vmax, vmin) in place
inline void cap(float& x, float& y, float vmax, float vmin) {
  float n = norm2(x, y);
  if (n < vmin) {
    x = 0.0f;
    y = 0.0f;
    return;
  }
  float s = vmax / std::max(n, vmax);
  x = x * s;
  y = y * s;
}

struct Contact {
  int j;
  float c, k;  // position and velocity coefficients of the pair
};

struct Pair {
  int i, j;
  float dx, dy, d, overlap;
};

struct Scratch {
  std::vector<float> gpos, best_d, rand_d, d_base, tx, ty, fx, fy, share, px0, py0, px, py, vx,
      vy, mcol, pcx, pcy, vcx, vcy, fpx, fpy, mpk, cnt, spx, spy, svx, svy, inv_m, ppx, ppy,
      pvx, pvy;
  std::vector<int> best, rand_, action, pidx, comp_start, comp_h, winner;
  std::vector<uint8_t> avail, released, delivered, lifted, alive, fdrop, fpick, carrying,
      in_lifted;
  std::vector<Contact> contacts;
  std::vector<Pair> pairs;
  std::vector<int> order, ncnt, nfill;
  std::vector<float> nx, ny;
};

template <typename T>
void ensure(std::vector<T>& v, size_t n) {
  if (v.size() < n) v.resize(n);
}

struct Env {
  // state (in place)
  float *pos, *vel, *energy, *waypoint, *p_pos, *p_vel;
  int64_t *holding, *grip, *stuck, *p_status, *holder;
  bool* p_picked;
  const int64_t* wp_key;
  // inputs
  const bool *p_present, *o_present, *present, *compat;
  const int64_t *g_effector, *program;
  const float *g_offset, *p_mass, *o_pos, *o_radius, *radius, *mass, *force, *efficiency, *keys;
  const int32_t* tables;
};

void robot_contacts(const Env& w, Scratch& s, int N, const Params& P) {
  // _robot_contacts_dense over the overlapping pairs only (the others add exact zeros), found by
  // sweep and prune along x (the order is kept between passes and ticks, so insertion sort
  // mostly has nothing to do); each robot sums its pairs in ascending partner order, as the
  // reference's row sums do. pos in s.pcx/pcy, vel in s.vcx/vcy (Jacobi: every pair of a pass
  // sees the positions and velocities from before the pass).
  float* px = s.pcx.data();
  float* py = s.pcy.data();
  float* vx = s.vcx.data();
  float* vy = s.vcy.data();
  float* inv_m = s.inv_m.data();
  float rmax = 0.0f;
  for (int i = 0; i < N; ++i) {
    inv_m[i] = 1.0f / s.mcol[i];
    if (w.present[i]) rmax = std::max(rmax, w.radius[i]);
  }
  const float window = 2.0f * rmax * 1.001f + 1e-6f;
  std::vector<int>& order = s.order;
  if (static_cast<int>(order.size()) != N) {
    order.resize(N);
    for (int i = 0; i < N; ++i) order[i] = i;
  }
  ensure(s.ncnt, static_cast<size_t>(N + 1));
  for (int64_t it = 0; it < P.collision_iters; ++it) {
    for (int a = 1; a < N; ++a) {  // insertion sort by x
      const int i = order[a];
      const float x = px[i];
      int b = a - 1;
      while (b >= 0 && px[order[b]] > x) {
        order[b + 1] = order[b];
        --b;
      }
      order[b + 1] = i;
    }
    s.pairs.clear();
    for (int a = 0; a < N; ++a) {
      const int i = order[a];
      if (!w.present[i]) continue;
      const float xi = px[i], yi = py[i], ri = w.radius[i];
      for (int b = a + 1; b < N; ++b) {
        const int j = order[b];
        const float dx = xi - px[j];
        if (-dx > window) break;
        if (!w.present[j]) continue;
        const float dy = yi - py[j];
        const float rsum = ri + w.radius[j];
        const float dd = dx * dx + dy * dy;
        if (dd >= rsum * rsum * 1.0001f + 1e-12f) continue;  // no overlap (margin for rounding)
        const float d = std::sqrt(dd);
        const float overlap = std::max(rsum - d, 0.0f);
        if (!(overlap > 0.0f)) continue;
        s.pairs.push_back({i, j, dx, dy, d, overlap});
      }
    }
    if (s.pairs.empty()) break;  // nothing overlaps: the later passes change nothing either
    // per robot, its pairs in ascending partner order
    std::fill(s.ncnt.begin(), s.ncnt.begin() + N + 1, 0);
    for (const Pair& p : s.pairs) {
      s.ncnt[p.i + 1]++;
      s.ncnt[p.j + 1]++;
    }
    for (int i = 0; i < N; ++i) s.ncnt[i + 1] += s.ncnt[i];
    s.contacts.resize(s.ncnt[N]);
    s.nfill.assign(s.ncnt.begin(), s.ncnt.begin() + N);
    for (const Pair& p : s.pairs) {
      const float inv_d = 1.0f / std::max(p.d, 1e-6f);
      const float inv_sum = inv_m[p.i] + inv_m[p.j];
      float k = 0.0f;
      if (it == 0) {
        const float vn = ((vx[p.i] - vx[p.j]) * p.dx + (vy[p.i] - vy[p.j]) * p.dy) * inv_d;
        if (vn < 0.0f) k = (-2.0f * vn / inv_sum) * inv_d;
      }
      s.contacts[s.nfill[p.i]++] = {p.j, p.overlap * (inv_m[p.i] / inv_sum) * inv_d, k};
      s.contacts[s.nfill[p.j]++] = {p.i, p.overlap * (inv_m[p.j] / inv_sum) * inv_d, k};
    }
    ensure(s.nx, static_cast<size_t>(N));
    ensure(s.ny, static_cast<size_t>(N));
    for (int i = 0; i < N; ++i) {
      s.nx[i] = px[i];
      s.ny[i] = py[i];
    }
    for (int i = 0; i < N; ++i) {
      const int lo = s.ncnt[i], hi = s.ncnt[i + 1];
      if (lo == hi) continue;
      Contact* c0 = s.contacts.data() + lo;
      std::sort(c0, c0 + (hi - lo), [](const Contact& a, const Contact& b) { return a.j < b.j; });
      float S = 0.0f, Bx = 0.0f, By = 0.0f, K = 0.0f, KBx = 0.0f, KBy = 0.0f;
      for (const Contact* ct = c0; ct != c0 + (hi - lo); ++ct) {
        S += ct->c;
        Bx += ct->c * px[ct->j];
        By += ct->c * py[ct->j];
        K += ct->k;
        KBx += ct->k * px[ct->j];
        KBy += ct->k * py[ct->j];
      }
      s.nx[i] = px[i] + px[i] * S - Bx;
      s.ny[i] = py[i] + py[i] * S - By;
      if (it == 0) {  // positions read here are the pass's old ones: s.nx is written apart
        vx[i] = vx[i] + inv_m[i] * (px[i] * K - KBx);
        vy[i] = vy[i] + inv_m[i] * (py[i] * K - KBy);
      }
    }
    for (int i = 0; i < N; ++i) {
      px[i] = s.nx[i];
      py[i] = s.ny[i];
    }
  }
}

void static_contacts(const Env& w, Scratch& s, int N, int O, const Params& P) {
  float* px = s.pcx.data();
  float* py = s.pcy.data();
  float* vx = s.vcx.data();
  float* vy = s.vcy.data();
  for (int i = 0; i < N; ++i) {
    float r = w.radius[i];
    float dpx = 0.0f, dpy = 0.0f, dvx = 0.0f, dvy = 0.0f;
    for (int o = 0; o < O; ++o) {
      float dx = px[i] - w.o_pos[2 * o], dy = py[i] - w.o_pos[2 * o + 1];
      const float rs = r + w.o_radius[o];
      const float dd = dx * dx + dy * dy;
      if (!w.o_present[o] || dd >= rs * rs * 1.0001f + 1e-12f) continue;  // adds exact zeros
      float d = std::sqrt(dd);
      float dm = std::max(d, 1e-6f);
      float nxo = dx / dm, nyo = dy / dm;
      float overlap = w.o_present[o] ? std::max(r + w.o_radius[o] - d, 0.0f) : 0.0f;
      dpx += nxo * overlap;
      dpy += nyo * overlap;
      float vn = vx[i] * nxo + vy[i] * nyo;
      float h = (overlap > 0.0f && vn < 0.0f) ? 2.0f * vn : 0.0f;
      dvx += nxo * h;
      dvy += nyo * h;
    }
    float x = px[i] + dpx, y = py[i] + dpy;
    float u = vx[i] - dvx, v = vy[i] - dvy;
    float lo = r, hi = P.arena - r;
    if ((x < lo && u < 0.0f) || (x > hi && u > 0.0f)) u = -u;
    if ((y < lo && v < 0.0f) || (y > hi && v > 0.0f)) v = -v;
    px[i] = std::min(std::max(x, lo), hi);
    py[i] = std::min(std::max(y, lo), hi);
    vx[i] = u;
    vy[i] = v;
  }
}

void run_env(const Env& w, Scratch& s, int N, int Q, int G, int O, int64_t t0, int64_t ticks,
             int64_t nc, const Params& P) {
  const int H = Q * G;
  for (auto* v : {&s.gpos}) ensure(*v, static_cast<size_t>(2 * H));
  for (auto* v : {&s.best_d, &s.rand_d, &s.d_base, &s.tx, &s.ty, &s.fx, &s.fy, &s.share, &s.px0,
                  &s.py0, &s.px, &s.py, &s.vx, &s.vy, &s.mcol, &s.pcx, &s.pcy, &s.vcx, &s.vcy,
                  &s.inv_m})
    ensure(*v, static_cast<size_t>(N));
  for (auto* v : {&s.fpx, &s.fpy, &s.mpk, &s.cnt, &s.spx, &s.spy, &s.svx, &s.svy, &s.ppx, &s.ppy,
                  &s.pvx, &s.pvy})
    ensure(*v, static_cast<size_t>(Q));
  for (auto* v : {&s.best, &s.rand_, &s.action, &s.pidx}) ensure(*v, static_cast<size_t>(N));
  ensure(s.winner, static_cast<size_t>(H));
  for (auto* v : {&s.avail, &s.released}) ensure(*v, static_cast<size_t>(H));
  for (auto* v : {&s.delivered, &s.lifted}) ensure(*v, static_cast<size_t>(Q));
  for (auto* v : {&s.alive, &s.fdrop, &s.fpick, &s.carrying, &s.in_lifted})
    ensure(*v, static_cast<size_t>(N));
  // the grip points each robot is compatible with, ascending (constant over the episode)
  ensure(s.comp_start, static_cast<size_t>(N + 1));
  s.comp_h.clear();
  for (int n = 0; n < N; ++n) {
    s.comp_start[n] = static_cast<int>(s.comp_h.size());
    for (int h = 0; h < H; ++h)
      if (w.compat[static_cast<int64_t>(n) * H + h]) s.comp_h.push_back(h);
  }
  s.comp_start[N] = static_cast<int>(s.comp_h.size());
  std::vector<int64_t> n_grips(Q);
  for (int q = 0; q < Q; ++q) {
    int64_t k = 0;
    for (int gg = 0; gg < G; ++gg) k += w.g_effector[q * G + gg] >= 0;
    n_grips[q] = std::max<int64_t>(k, 1);
  }
  std::vector<uint8_t> any_exists(Q);
  for (int q = 0; q < Q; ++q) {
    bool a = false;
    for (int gg = 0; gg < G; ++gg) a = a || (w.g_effector[q * G + gg] >= 0);
    any_exists[q] = a;
  }
  const float base = P.base;
  float* pos = w.pos;
  float* vel = w.vel;

  for (int64_t tick = 0; tick < ticks; ++tick) {
    const int64_t t_new = t0 + tick + 1;
    // ---------------- sense
    for (int h = 0; h < H; ++h) {
      int q = h / G;
      s.gpos[2 * h] = w.p_pos[2 * q] + w.g_offset[2 * h];
      s.gpos[2 * h + 1] = w.p_pos[2 * q + 1] + w.g_offset[2 * h + 1];
      s.avail[h] = (w.g_effector[h] >= 0) && (w.holder[h] < 0) && (w.p_status[q] != DELIVERED) &&
                   w.p_present[q];
    }
    for (int n = 0; n < N; ++n) {
      const float x = pos[2 * n], y = pos[2 * n + 1];
      const bool alive = w.present[n] && (w.energy[n] > 0.0f);
      s.alive[n] = alive;
      const bool free_ = alive && (w.holding[n] < 0);
      float bd = INF, rk = -1.0f;
      int b = 0, r = 0;
      if (free_) {
        const float* key = w.keys + static_cast<int64_t>(n) * H;
        for (int c = s.comp_start[n]; c < s.comp_start[n + 1]; ++c) {
          int h = s.comp_h[c];
          if (!s.avail[h]) continue;
          float d = norm2(s.gpos[2 * h] - x, s.gpos[2 * h + 1] - y);
          if (d < bd) {
            bd = d;
            b = h;
          }
          if (key[h] > rk) {
            rk = key[h];
            r = h;
          }
        }
      }
      const bool has_target = bd < INF;
      float rd = INF;
      if (has_target) rd = norm2(s.gpos[2 * r] - x, s.gpos[2 * r + 1] - y);
      s.best[n] = b;
      s.best_d[n] = bd;
      s.rand_[n] = r;
      s.rand_d[n] = rd;
      const float db = norm2(x - base, y - base);
      s.d_base[n] = db;
      const bool holding = w.holding[n] >= 0;
      const bool at_base = db <= P.base_radius;
      const bool wp_done =
          norm2(w.waypoint[2 * n] - x, w.waypoint[2 * n + 1] - y) <= P.reach;
      // combo_index: condition bits set on FAILURE, action statuses in base 3 from 16
      int64_t idx = (holding ? 0 : 1) + (bd <= P.near_ ? 0 : 2) + (at_base ? 0 : 4) +
                    (w.stuck[n] >= P.stuck_ticks ? 0 : 8);
      int mp = !has_target ? S_FAILURE : (bd <= P.reach ? S_SUCCESS : S_RUNNING);
      int mb = at_base ? S_SUCCESS : S_RUNNING;
      int rw = wp_done ? S_SUCCESS : S_RUNNING;
      int pu = bd <= P.reach ? S_SUCCESS : S_FAILURE;
      int dr = holding ? S_SUCCESS : S_FAILURE;
      int mr = !has_target ? S_FAILURE : (rd <= P.reach ? S_SUCCESS : S_RUNNING);
      idx += 16 * (mp + 3 * (mb + 3 * (rw + 3 * (pu + 3 * (dr + 3 * mr)))));
      const int32_t packed = w.tables[w.program[n] * nc + idx];
      s.action[n] = alive ? (packed & 0xF) : NOP;
      s.fdrop[n] = alive && ((packed >> (ACT_DROP - ACT_MOVE_TO_PACK + FIRED_SHIFT)) & 1);
      s.fpick[n] = alive && ((packed >> (ACT_PICK_UP - ACT_MOVE_TO_PACK + FIRED_SHIFT)) & 1);
    }
    // ---------------- drop
    std::fill(s.released.begin(), s.released.begin() + H, 0);
    for (int q = 0; q < Q; ++q) s.delivered[q] = w.p_status[q] == DELIVERED;
    for (int n = 0; n < N; ++n) {
      const int64_t hq = w.holding[n];
      const bool drop = s.fdrop[n] && hq >= 0;
      s.fdrop[n] = drop;
      if (drop) {
        s.released[hq * G + w.grip[n]] = 1;
        if (s.d_base[n] <= P.base_radius) s.delivered[hq] = 1;
      }
    }
    for (int h = 0; h < H; ++h)
      if (s.released[h] || s.delivered[h / G]) w.holder[h] = -1;
    for (int n = 0; n < N; ++n) {
      const int64_t hq = w.holding[n];
      const bool lost = hq >= 0 && s.delivered[hq];
      if (s.fdrop[n] || lost) w.holding[n] = -1;
    }
    // ---------------- pick up: ties to the lowest robot index
    for (int h = 0; h < H; ++h) s.winner[h] = N;
    for (int n = 0; n < N; ++n) {
      const bool pick = s.fpick[n] && w.holding[n] < 0 && s.best_d[n] <= P.reach;
      s.fpick[n] = pick;
      if (pick && s.winner[s.best[n]] > n) s.winner[s.best[n]] = n;
    }
    for (int n = 0; n < N; ++n) {
      if (s.fpick[n] && s.winner[s.best[n]] == n) {
        w.holder[s.best[n]] = n;
        w.holding[n] = s.best[n] / G;
        w.grip[n] = s.best[n] % G;
      }
    }
    for (int q = 0; q < Q; ++q) {
      bool held_any = false, all = true;
      for (int gg = 0; gg < G; ++gg) {
        const bool held = w.holder[q * G + gg] >= 0;
        held_any = held_any || held;
        all = all && (held || w.g_effector[q * G + gg] < 0);
      }
      const bool lifted = all && any_exists[q] && !s.delivered[q];
      s.lifted[q] = lifted;
      w.p_status[q] = s.delivered[q] ? DELIVERED : (held_any ? HELD : GROUND);
      w.p_picked[q] = w.p_picked[q] || lifted;
    }
    // ---------------- targets, PD control, free robots
    for (int n = 0; n < N; ++n) {
      const float x = pos[2 * n], y = pos[2 * n + 1];
      s.px0[n] = x;
      s.py0[n] = y;
      float tx = x, ty = y;
      const int a = s.action[n];
      if (a == ACT_MOVE_TO_PACK && s.best_d[n] < INF) {
        tx = s.gpos[2 * s.best[n]];
        ty = s.gpos[2 * s.best[n] + 1];
      } else if (a == ACT_MOVE_TO_RANDOM_PACK && s.rand_d[n] < INF) {
        tx = s.gpos[2 * s.rand_[n]];
        ty = s.gpos[2 * s.rand_[n] + 1];
      } else if (a == ACT_MOVE_TO_BASE) {
        tx = base;
        ty = base;
      } else if (a == ACT_RANDOM_WALK) {
        tx = w.waypoint[2 * n];
        ty = w.waypoint[2 * n + 1];
      }
      s.tx[n] = tx;
      s.ty[n] = ty;
      const int64_t hq = w.holding[n];
      const bool carrying = hq >= 0;
      s.carrying[n] = carrying;
      const float share = carrying ? w.p_mass[hq] / static_cast<float>(n_grips[hq]) : 0.0f;
      s.share[n] = share;
      const float m_ctrl = w.mass[n] + share;
      float vdx = P.kp * (tx - x), vdy = P.kp * (ty - y);
      cap(vdx, vdy, P.v_cap, 0.0f);
      const float vx0 = vel[2 * n], vy0 = vel[2 * n + 1];
      float fx = m_ctrl * (P.kv * (vdx - vx0) + P.drag * vdx);
      float fy = m_ctrl * (P.kv * (vdy - vy0) + P.drag * vdy);
      const float fmax = s.alive[n] ? w.force[n] : 0.0f;
      const float sc = std::min(fmax / std::max(norm2(fx, fy), 1e-9f), 1.0f);
      fx = fx * sc;
      fy = fy * sc;
      s.fx[n] = fx;
      s.fy[n] = fy;
      float ux = vx0 + P.dt * (fx / w.mass[n] - P.drag * vx0);
      float uy = vy0 + P.dt * (fy / w.mass[n] - P.drag * vy0);
      cap(ux, uy, P.v_cap, P.rest_speed);
      s.vx[n] = ux;
      s.vy[n] = uy;
      s.px[n] = x + P.dt * ux;
      s.py[n] = y + P.dt * uy;
      const bool in_lifted = carrying && s.lifted[hq];
      s.in_lifted[n] = in_lifted;
      s.pidx[n] = in_lifted ? static_cast<int>(hq) : Q;
    }
    // ---------------- lifted packages: one rigid body with their carriers
    for (int q = 0; q < Q; ++q) {
      s.fpx[q] = 0.0f;
      s.fpy[q] = 0.0f;
      s.mpk[q] = 0.0f;
      s.cnt[q] = 0.0f;
    }
    for (int n = 0; n < N; ++n) {
      const int q = s.pidx[n];
      if (q >= Q) continue;
      s.fpx[q] += s.fx[n];
      s.fpy[q] += s.fy[n];
      s.mpk[q] += w.mass[n];
      s.cnt[q] += 1.0f;
    }
    for (int q = 0; q < Q; ++q) {
      float vx = 0.0f, vy = 0.0f;
      if (s.lifted[q]) {
        const float m = w.p_mass[q] + s.mpk[q];
        const float pvx = w.p_vel[2 * q], pvy = w.p_vel[2 * q + 1];
        vx = pvx + P.dt * (s.fpx[q] / m - P.drag * pvx);
        vy = pvy + P.dt * (s.fpy[q] / m - P.drag * pvy);
        cap(vx, vy, P.v_cap, P.rest_speed);
      }
      w.p_vel[2 * q] = vx;
      w.p_vel[2 * q + 1] = vy;
      w.p_pos[2 * q] = w.p_pos[2 * q] + P.dt * vx;
      w.p_pos[2 * q + 1] = w.p_pos[2 * q + 1] + P.dt * vy;
    }
    for (int n = 0; n < N; ++n) {
      if (s.carrying[n]) {
        const int64_t hq = w.holding[n];
        const int64_t h = hq * G + w.grip[n];
        s.px[n] = w.p_pos[2 * hq] + w.g_offset[2 * h];
        s.py[n] = w.p_pos[2 * hq + 1] + w.g_offset[2 * h + 1];
        s.vx[n] = w.p_vel[2 * hq];
        s.vy[n] = w.p_vel[2 * hq + 1];
      }
      const bool waiting = s.carrying[n] && !s.in_lifted[n];
      s.mcol[n] = waiting ? P.anchor_mass : w.mass[n] + s.share[n];
      s.pcx[n] = s.px[n];
      s.pcy[n] = s.py[n];
      s.vcx[n] = s.vx[n];
      s.vcy[n] = s.vy[n];
    }
    // ---------------- contacts; carriers pass their correction on to their package
    robot_contacts(w, s, N, P);
    static_contacts(w, s, N, O, P);
    for (int q = 0; q < Q; ++q) {
      s.spx[q] = 0.0f;
      s.spy[q] = 0.0f;
      s.svx[q] = 0.0f;
      s.svy[q] = 0.0f;
    }
    for (int n = 0; n < N; ++n) {
      const int q = s.pidx[n];
      if (q >= Q) continue;
      s.spx[q] += s.pcx[n] - s.px[n];
      s.spy[q] += s.pcy[n] - s.py[n];
      s.svx[q] += s.vcx[n];
      s.svy[q] += s.vcy[n];
    }
    for (int q = 0; q < Q; ++q) {
      if (!s.lifted[q]) continue;
      const float c = std::max(s.cnt[q], 1.0f);
      w.p_pos[2 * q] = w.p_pos[2 * q] + s.spx[q] / c;
      w.p_pos[2 * q + 1] = w.p_pos[2 * q + 1] + s.spy[q] / c;
      w.p_vel[2 * q] = s.svx[q] / c;
      w.p_vel[2 * q + 1] = s.svy[q] / c;
    }
    // ---------------- final positions, energy, stuck, waypoints
    const bool period = (t_new % P.waypoint_period) == 0;
    for (int n = 0; n < N; ++n) {
      float x, y, u, v;
      if (s.carrying[n]) {
        const int64_t hq = w.holding[n];
        const int64_t h = hq * G + w.grip[n];
        x = w.p_pos[2 * hq] + w.g_offset[2 * h];
        y = w.p_pos[2 * hq + 1] + w.g_offset[2 * h + 1];
        u = w.p_vel[2 * hq];
        v = w.p_vel[2 * hq + 1];
      } else {
        x = s.pcx[n];
        y = s.pcy[n];
        u = s.vcx[n];
        v = s.vcy[n];
      }
      pos[2 * n] = x;
      pos[2 * n + 1] = y;
      vel[2 * n] = u;
      vel[2 * n + 1] = v;
      const float p_mech = std::max(s.fx[n] * u + s.fy[n] * v, 0.0f);
      const float used = P.dt * (p_mech / w.efficiency[n] + P.idle_power);
      w.energy[n] = w.present[n] ? std::max(w.energy[n] - used, 0.0f) : 0.0f;
      const int a = s.action[n];
      const bool moving = a == ACT_MOVE_TO_PACK || a == ACT_MOVE_TO_BASE || a == ACT_RANDOM_WALK ||
                          a == ACT_MOVE_TO_RANDOM_PACK;
      const bool trying = moving && norm2(s.tx[n] - s.px0[n], s.ty[n] - s.py0[n]) > P.reach;
      const bool slow = norm2(x - s.px0[n], y - s.py0[n]) < P.stuck_slow;
      w.stuck[n] = (trying && slow) ? w.stuck[n] + 1 : 0;
      const bool redraw =
          norm2(w.waypoint[2 * n] - x, w.waypoint[2 * n + 1] - y) <= P.reach || period;
      if (redraw) {
        w.waypoint[2 * n] = P.wp_lo + P.wp_span * waypoint_u(w.wp_key[2 * n], t_new);
        w.waypoint[2 * n + 1] = P.wp_lo + P.wp_span * waypoint_u(w.wp_key[2 * n + 1], t_new);
      }
    }
  }
}

template <typename T>
T* ptr(const torch::Tensor& t) {
  return t.data_ptr<T>();
}

}  // namespace

// state: t, pos, vel, energy, holding, grip, stuck, waypoint, p_pos, p_vel, p_status, holder,
//        p_picked, wp_key (contiguous, updated in place; t too)
// inputs: p_present, g_effector, g_offset, p_mass, o_pos, o_radius, o_present, radius, mass,
//         force, efficiency, present, program, compat, keys, tables
void run_ticks(std::vector<torch::Tensor> st, std::vector<torch::Tensor> in,
               std::vector<double> fp, std::vector<int64_t> ip, int64_t ticks) {
  TORCH_CHECK(st.size() == 14 && in.size() == 16, "fused tick: wrong number of tensors");
  const auto& pos = st[1];
  const int64_t E = pos.size(0), N = pos.size(1);
  const int64_t Q = in[1].size(1), G = in[1].size(2), O = in[4].size(1);
  const int64_t H = Q * G;
  const int64_t nc = in[15].size(1);
  Params P;
  P.arena = static_cast<float>(fp[0]);
  P.base_radius = static_cast<float>(fp[1]);
  P.dt = static_cast<float>(fp[2]);
  P.drag = static_cast<float>(fp[3]);
  P.v_cap = static_cast<float>(fp[4]);
  P.kp = static_cast<float>(fp[5]);
  P.kv = static_cast<float>(fp[6]);
  P.reach = static_cast<float>(fp[7]);
  P.near_ = static_cast<float>(fp[8]);
  P.idle_power = static_cast<float>(fp[9]);
  P.stuck_slow = static_cast<float>(fp[10]);
  P.anchor_mass = static_cast<float>(fp[11]);
  P.rest_speed = static_cast<float>(fp[12]);
  P.cell_size = static_cast<float>(fp[13]);
  P.wp_lo = static_cast<float>(fp[14]);
  P.wp_span = static_cast<float>(fp[15]);
  P.base = static_cast<float>(fp[16]);
  P.stuck_ticks = ip[0];
  P.waypoint_period = ip[1];
  P.collision_iters = ip[2];
  P.grid = ip[3];
  const int64_t t0 = st[0].item<int64_t>();
  at::parallel_for(0, E, 1, [&](int64_t begin, int64_t end) {
    Scratch s;
    for (int64_t e = begin; e < end; ++e) {
      Env w;
      w.pos = ptr<float>(st[1]) + e * N * 2;
      w.vel = ptr<float>(st[2]) + e * N * 2;
      w.energy = ptr<float>(st[3]) + e * N;
      w.holding = ptr<int64_t>(st[4]) + e * N;
      w.grip = ptr<int64_t>(st[5]) + e * N;
      w.stuck = ptr<int64_t>(st[6]) + e * N;
      w.waypoint = ptr<float>(st[7]) + e * N * 2;
      w.p_pos = ptr<float>(st[8]) + e * Q * 2;
      w.p_vel = ptr<float>(st[9]) + e * Q * 2;
      w.p_status = ptr<int64_t>(st[10]) + e * Q;
      w.holder = ptr<int64_t>(st[11]) + e * H;
      w.p_picked = ptr<bool>(st[12]) + e * Q;
      w.wp_key = ptr<int64_t>(st[13]) + e * N * 2;
      w.p_present = ptr<bool>(in[0]) + e * Q;
      w.g_effector = ptr<int64_t>(in[1]) + e * H;
      w.g_offset = ptr<float>(in[2]) + e * H * 2;
      w.p_mass = ptr<float>(in[3]) + e * Q;
      w.o_pos = ptr<float>(in[4]) + e * O * 2;
      w.o_radius = ptr<float>(in[5]) + e * O;
      w.o_present = ptr<bool>(in[6]) + e * O;
      w.radius = ptr<float>(in[7]) + e * N;
      w.mass = ptr<float>(in[8]) + e * N;
      w.force = ptr<float>(in[9]) + e * N;
      w.efficiency = ptr<float>(in[10]) + e * N;
      w.present = ptr<bool>(in[11]) + e * N;
      w.program = ptr<int64_t>(in[12]) + e * N;
      w.compat = ptr<bool>(in[13]) + e * N * H;
      w.keys = ptr<float>(in[14]) + e * N * H;
      w.tables = ptr<int32_t>(in[15]);
      run_env(w, s, static_cast<int>(N), static_cast<int>(Q), static_cast<int>(G),
              static_cast<int>(O), t0, ticks, nc, P);
    }
  });
  st[0].fill_(t0 + ticks);
}

// bt.build_tables' walk (`_build_chunk`), every (program, leaf-status combination) pair from
// the program's first leaf through its continuations to the end of the tick; the same packed
// int32 words. ops [P, L], start [P], cont [P, L, 2] (long, from `_continuations`),
// col_status [14 * NC] (long: status of opcode o under combination c at o * NC + c).
torch::Tensor walk_tables(torch::Tensor ops, torch::Tensor start, torch::Tensor cont,
                          torch::Tensor col_status) {
  TORCH_CHECK(ops.dtype() == torch::kLong && start.dtype() == torch::kLong &&
                  cont.dtype() == torch::kLong && col_status.dtype() == torch::kLong,
              "walk_tables: long tensors");
  ops = ops.contiguous();
  start = start.contiguous();
  cont = cont.contiguous();
  col_status = col_status.contiguous();
  const int64_t P = ops.size(0), L = ops.size(1);
  const int64_t NC = col_status.numel() / 14;
  auto out = torch::empty({P, NC}, torch::dtype(torch::kInt32));
  const int64_t* op = ops.data_ptr<int64_t>();
  const int64_t* st0 = start.data_ptr<int64_t>();
  const int64_t* ct = cont.data_ptr<int64_t>();
  const int64_t* cs = col_status.data_ptr<int64_t>();
  int32_t* o = out.data_ptr<int32_t>();
  constexpr int64_t STATUS_SHIFT = 10;
  at::parallel_for(0, P, 1, [&](int64_t b, int64_t e) {
    for (int64_t p = b; p < e; ++p) {
      const int64_t* pop = op + p * L;
      const int64_t* pct = ct + p * L * 2;
      for (int64_t c = 0; c < NC; ++c) {
        int64_t s = st0[p];
        int64_t acc = 0, fin = -1;
        for (int64_t step = 0; step <= L && s < L; ++step) {
          const int64_t code = pop[s];
          const int64_t status = cs[code * NC + c];
          if (status == S_RUNNING) {
            fin = code | (static_cast<int64_t>(S_RUNNING) << STATUS_SHIFT);
            break;
          }
          if (status == S_SUCCESS) {
            if (code >= ACT_MOVE_TO_PACK && code <= ACT_MOVE_TO_RANDOM_PACK)
              acc |= int64_t(1) << (FIRED_SHIFT + code - ACT_MOVE_TO_PACK);
            s = pct[s * 2];
          } else {
            s = pct[s * 2 + 1];
          }
        }
        if (fin < 0) {
          TORCH_CHECK(s >= L && s <= L + 1, "walk_tables: a walk did not end");
          fin = NOP | ((s - L) << STATUS_SHIFT);
        }
        o[p * NC + c] = static_cast<int32_t>(fin | acc);
      }
    }
  });
  return out;
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("run_ticks", &run_ticks, "the fused CPU tick, `ticks` times, in place");
  m.def("walk_tables", &walk_tables, "bt.build_tables' walk over (program, combination) pairs");
}
