// Tile-based Gaussian compositing on the CPU (OpenMP over 8x8 tiles), forward and backward, and the
// forward's per-pixel weights (contributions) with the gather/scatter that redraw colours from them.
//
// Inputs are the projected, culled Gaussians of all cameras ("entries"): 2D means in pixels
// (pixel centres at +0.5), conics (inverse 2D covariance a, b, c), per-entry colour channels and
// opacities. The alpha rules are the engine's (see rasterizer/__init__.py): skip a Gaussian when
// alpha < 1/255 (tested in log space before exp), clamp alpha to 0.99, stop a pixel before the
// Gaussian that would bring its transmittance below 1e-4. The backward walks each pixel's list
// back to front and recovers the transmittance by division, so nothing per pair is stored.
#include <torch/extension.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <type_traits>
#include <vector>

namespace {

constexpr int kTile = 8;
constexpr int kMaxChannels = 32;

template <typename T>
struct Rules {  // the alpha rules in the kernel's precision
  static constexpr T alpha_max = T(0.99);
  static constexpr T transmittance_min = T(1e-4);
};

template <typename T>
struct Splat {
  T mx, my, a, b, c, opacity, log_min;  // log_min: power below which alpha < 1/255
  int32_t row_lo, row_hi;                // the tile rows its alpha >= 1/255 ellipse can reach
};

int num_threads() { return std::max(1, at::get_num_threads()); }

void check_inputs(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& colors,
                  const torch::Tensor& opacities) {
  const auto dtype = means2d.dtype();
  TORCH_CHECK(dtype == torch::kFloat32 || dtype == torch::kFloat64, "inputs must be float32 or float64");
  for (const auto* t : {&means2d, &conics, &colors, &opacities})
    TORCH_CHECK(t->dtype() == dtype && t->is_contiguous(), "inputs must be contiguous and of one dtype");
  TORCH_CHECK(means2d.dim() == 2 && colors.dim() == 2, "means2d must be (M,2) and colors (M,C)");
  TORCH_CHECK(colors.size(1) >= 1 && colors.size(1) <= kMaxChannels, "colors must have 1..32 channels");
}

// Rows [lo, hi] of a tile (clipped to [0, last]) whose pixel centres lie within `half` of `centre`;
// every row when the extent or the centre is not finite or beyond 1e6 px.
template <typename T>
inline void row_range(T centre, T half, int64_t origin, int32_t last, int32_t& lo, int32_t& hi) {
  lo = 0, hi = last;
  if (!(half < T(1e6)) || !(std::abs(centre) < T(1e6))) return;  // also NaN
  const T first = std::ceil(centre - half - T(0.5)) - T(origin), final = std::floor(centre + half - T(0.5)) - T(origin);
  lo = first > T(0) ? static_cast<int32_t>(std::min(first, T(last + 1))) : 0;
  hi = final < T(last) ? static_cast<int32_t>(std::max(final, T(-1))) : last;
}

// Per entry, what gather_tile needs beyond the raw arrays: log_min = -log(255 o) (the power below which
// alpha < 1/255) and the half height of the alpha >= 1/255 ellipse, sqrt(r2 cov_yy) with cov = conic^-1
// and r2 = -2 log_min, padded by 1e-2 px so that float rounding cannot cut off a lit pixel (infinite
// for a degenerate conic: every row).
template <typename T>
struct Footprints {
  std::vector<T> log_min, half_height;

  Footprints(const T* conics, const T* opacities, int64_t m) : log_min(m), half_height(m) {
#pragma omp parallel for num_threads(num_threads()) schedule(static)
    for (int64_t g = 0; g < m; ++g) {
      const T a = conics[3 * g], b = conics[3 * g + 1], c = conics[3 * g + 2];
      const T lm = -std::log(T(255) * opacities[g]), det = a * c - b * b, r2 = T(-2) * lm;
      log_min[g] = lm;
      half_height[g] = det > T(0) && r2 >= T(0) ? std::sqrt(r2 * a / det) + T(1e-2) : T(INFINITY);
    }
  }
};

// Gathers the splats of one tile's list into a contiguous local buffer (cache friendly), each with the
// rows of the tile it can reach.
template <typename T>
void gather_tile(const T* means2d, const T* conics, const T* opacities, const Footprints<T>& foot,
                 const int32_t* pair_gauss, int64_t begin, int64_t end, int64_t y0, int32_t last_row,
                 std::vector<Splat<T>>& out) {
  out.resize(end - begin);
  for (int64_t k = begin; k < end; ++k) {
    const int32_t g = pair_gauss[k];
    Splat<T>& s = out[k - begin];
    s = Splat<T>{means2d[2 * g], means2d[2 * g + 1], conics[3 * g], conics[3 * g + 1], conics[3 * g + 2],
                 opacities[g], foot.log_min[g], 0, last_row};
    row_range(s.my, foot.half_height[g], y0, last_row, s.row_lo, s.row_hi);
  }
}

}  // namespace

// Entry indices in ascending depth order, ties by index (a stable LSD radix sort of the float32 bits, 3 passes
// of 11 bits: linear, ~11x faster than torch.argsort on 2 cores). Negative depths sort before positive ones
// (the usual sign flip; -0 as +0), so any finite depth is ordered as a float comparison would.
torch::Tensor depth_order(torch::Tensor depths) {
  TORCH_CHECK(depths.dtype() == torch::kFloat32 && depths.is_contiguous() && depths.dim() == 1,
              "depths must be a contiguous float32 (M,) tensor");
  const int64_t m = depths.size(0);
  TORCH_CHECK(m < INT32_MAX, "too many entries to sort");
  const uint32_t* bits = reinterpret_cast<const uint32_t*>(depths.data_ptr<float>());
  constexpr int kBits = 11, kPasses = 3;
  constexpr uint32_t kBuckets = 1u << kBits, kMask = kBuckets - 1;
  std::vector<uint32_t> keys(m), keys_tmp(m);
  std::vector<int32_t> idx(m), idx_tmp(m);
  std::vector<int64_t> count(kPasses * kBuckets, 0);
  for (int64_t i = 0; i < m; ++i) {
    const uint32_t b = bits[i] == 0x80000000u ? 0u : bits[i];  // -0 sorts as +0
    const uint32_t k = (b & 0x80000000u) ? ~b : (b | 0x80000000u);
    keys[i] = k;
    idx[i] = static_cast<int32_t>(i);
    for (int p = 0; p < kPasses; ++p) ++count[p * kBuckets + ((k >> (p * kBits)) & kMask)];
  }
  for (int p = 0; p < kPasses; ++p) {
    int64_t* c = count.data() + p * kBuckets;
    int64_t total = 0;
    for (uint32_t d = 0; d < kBuckets; ++d) {
      const int64_t n = c[d];
      c[d] = total;
      total += n;
    }
    const int shift = p * kBits;
    for (int64_t i = 0; i < m; ++i) {
      const int64_t slot = c[(keys[i] >> shift) & kMask]++;
      keys_tmp[slot] = keys[i];
      idx_tmp[slot] = idx[i];
    }
    keys.swap(keys_tmp);
    idx.swap(idx_tmp);
  }
  auto order = torch::empty({m}, torch::dtype(torch::kInt64));
  int64_t* out = order.data_ptr<int64_t>();
  for (int64_t i = 0; i < m; ++i) out[i] = idx[i];
  return order;
}

// Counting sort of (entry, tile) pairs by tile; entries are visited in the given depth order, so
// each tile's list comes out sorted front to back. Returns (tile_offsets[n_tiles+1], pair_gauss[P]).
// Parallel: each thread counts, then scatters, one contiguous run of the depth order; a tile's slots
// are handed out run by run, so the lists are exactly the serial sort's.
std::vector<torch::Tensor> bin_tiles(torch::Tensor tile_bbox, torch::Tensor cam_ids, torch::Tensor depth_order,
                                     int64_t n_cams, int64_t tiles_x, int64_t tiles_y) {
  TORCH_CHECK(tile_bbox.dtype() == torch::kInt32 && tile_bbox.is_contiguous(), "tile_bbox must be int32 (M,4)");
  TORCH_CHECK(cam_ids.dtype() == torch::kInt32 && cam_ids.is_contiguous(), "cam_ids must be int32 (M,)");
  TORCH_CHECK(depth_order.dtype() == torch::kInt64 && depth_order.is_contiguous(), "depth_order must be int64 (M,)");
  const int64_t m = tile_bbox.size(0);
  const int64_t tiles_per_cam = tiles_x * tiles_y;
  const int64_t n_tiles = n_cams * tiles_per_cam;
  const int32_t* bb = tile_bbox.data_ptr<int32_t>();
  const int32_t* cam = cam_ids.data_ptr<int32_t>();
  const int64_t* order = depth_order.data_ptr<int64_t>();
  const int runs = static_cast<int>(std::min<int64_t>(num_threads(), std::max<int64_t>(1, m / 4096)));
  auto run_begin = [&](int r) { return m * r / runs; };
  auto for_each_tile = [&](int64_t i, auto&& visit) {
    const int32_t* b = bb + 4 * i;
    const int64_t base = cam[i] * tiles_per_cam;
    for (int32_t ty = b[1]; ty <= b[3]; ++ty)
      for (int32_t tx = b[0]; tx <= b[2]; ++tx) visit(base + ty * tiles_x + tx);
  };

  std::vector<int64_t> slots(int64_t(runs) * n_tiles, 0);  // per run: its pairs per tile, then its first slot
#pragma omp parallel for num_threads(runs) schedule(static, 1)
  for (int r = 0; r < runs; ++r) {
    int64_t* count = slots.data() + int64_t(r) * n_tiles;
    for (int64_t k = run_begin(r); k < run_begin(r + 1); ++k) for_each_tile(order[k], [&](int64_t t) { ++count[t]; });
  }
  auto offsets = torch::empty({n_tiles + 1}, torch::dtype(torch::kInt32));
  int32_t* off = offsets.data_ptr<int32_t>();
  int64_t total = 0;
  for (int64_t t = 0; t < n_tiles; ++t) {
    off[t] = static_cast<int32_t>(total);
    for (int r = 0; r < runs; ++r) {
      int64_t& slot = slots[int64_t(r) * n_tiles + t];
      const int64_t n = slot;
      slot = total;
      total += n;
    }
    TORCH_CHECK(total < INT32_MAX, "too many Gaussian/tile pairs for one render; render fewer cameras at once");
  }
  off[n_tiles] = static_cast<int32_t>(total);
  auto pairs = torch::empty({total}, torch::dtype(torch::kInt32));
  int32_t* pg = pairs.data_ptr<int32_t>();
#pragma omp parallel for num_threads(runs) schedule(static, 1)
  for (int r = 0; r < runs; ++r) {
    int64_t* cursor = slots.data() + int64_t(r) * n_tiles;
    for (int64_t k = run_begin(r); k < run_begin(r + 1); ++k) {
      const int64_t i = order[k];
      for_each_tile(i, [&](int64_t t) { pg[cursor[t]++] = static_cast<int32_t>(i); });
    }
  }
  return {offsets, pairs};
}

namespace {

// Both sweeps go splat by splat over a tile's depth-sorted list and, for each splat, over the tile's
// rows it can reach whose pixels are still compositing; a row's 8 pixels are vector lanes and a pixel
// that is done or not hit is a masked lane, so every pixel computes what a pixel-by-pixel loop would,
// in the same order (~2x faster than that loop with AVX2 lanes). NC > 0 fixes the channel count at
// compile time (3: RGB, 4: RGB + depth) so the channel loops unroll; NC = 0 reads it at run time.
template <int NC>
struct Channels : std::integral_constant<int, NC> {};

template <typename F>
void dispatch_channels(int64_t c, F&& run) {
  if (c == 3) return run(Channels<3>{});
  if (c == 4) return run(Channels<4>{});
  run(Channels<0>{});
}

// One tile row as a vector of 8 lanes (GCC vector extensions: AVX when compiled for it, else pairs of
// SSE registers), with its integer mask type of the same width.
template <typename T>
struct Lanes;
template <>
struct Lanes<float> {
  typedef float V __attribute__((vector_size(32)));
  typedef int32_t M __attribute__((vector_size(32)));
  typedef int32_t I;
};
template <>
struct Lanes<double> {
  typedef double V __attribute__((vector_size(64)));
  typedef int64_t M __attribute__((vector_size(64)));
  typedef int64_t I;
};

// exp of every lane, for the powers the kernels evaluate (in [log(1/255) - 1, 0]). Float lanes: 2^n e^f
// with n = round(x / ln 2) and a degree-7 Taylor polynomial on |f| <= ln(2)/2 (relative error < 1e-8,
// below float's resolution), written with vector operations so that it vectorises; double lanes
// (tests, gradcheck) use std::exp.
inline Lanes<float>::V exp_lanes(Lanes<float>::V x) {
  using V = Lanes<float>::V;
  using M = Lanes<float>::M;
  x = x < -87.0f ? V{} - 87.0f : x;
  const V n = (x * 1.44269504088896341f + 12582912.0f) - 12582912.0f;
  const V f = (x - n * 0.693145751953125f) - n * 1.42860682030941723212e-6f;
  V p = V{} + 1.0f / 5040.0f;
  p = p * f + 1.0f / 720.0f;
  p = p * f + 1.0f / 120.0f;
  p = p * f + 1.0f / 24.0f;
  p = p * f + 1.0f / 6.0f;
  p = p * f + 0.5f;
  p = p * f + 1.0f;
  p = p * f + 1.0f;
  const M bits = (__builtin_convertvector(n, M) + 127) << 23;
  return p * (V)bits;  // a cast between vector types of one size reinterprets the bits
}

inline Lanes<double>::V exp_lanes(Lanes<double>::V x) {
  for (int l = 0; l < kTile; ++l) x[l] = std::exp(x[l]);
  return x;
}

template <typename M>
inline bool any_lane(M mask) {
  bool any = false;
  for (int l = 0; l < kTile; ++l) any |= mask[l] != 0;
  return any;
}

// Power of a splat's Gaussian at a row of pixel centres (offsets dx, dy from them); one expression for
// both sweeps, so that forward and backward make the same skip decisions.
template <typename T, typename V>
inline V power_lanes(const Splat<T>& s, V dx, V dy) {
  return T(-0.5) * (s.a * dx * dx + s.c * dy * dy) - s.b * dx * dy;
}

struct TileOrigin {
  int64_t cam, x0, y0;
  int32_t last_x, last_y;  // last tile-relative column and row inside the image

  TileOrigin(int64_t tile, int64_t tiles_x, int64_t tiles_y, int64_t width, int64_t height)
      : cam(tile / (tiles_x * tiles_y)),
        x0((tile % (tiles_x * tiles_y) % tiles_x) * kTile),
        y0((tile % (tiles_x * tiles_y) / tiles_x) * kTile),
        last_x(static_cast<int32_t>(std::min<int64_t>(kTile, width - x0) - 1)),
        last_y(static_cast<int32_t>(std::min<int64_t>(kTile, height - y0) - 1)) {}

  int64_t pixel(int64_t width, int64_t height, int32_t row, int32_t col) const {
    return (cam * height + y0 + row) * width + x0 + col;
  }
};

// The front-to-back sweep of forward() and contributions(): per tile, per splat in depth order, the weight
// w = alpha T each still-compositing pixel gives it, handed to a Sink per thread (begin(tile), add(row, pair
// index, w), end(tile)); writes each pixel's final transmittance and one past its last contributing pair.
template <typename T, typename MakeSink>
void sweep(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& opacities,
           const torch::Tensor& tile_offsets, const torch::Tensor& pair_gauss, int64_t n_cams, int64_t width,
           int64_t height, torch::Tensor& out_t, torch::Tensor& out_end, MakeSink&& make_sink) {
  using V = typename Lanes<T>::V;
  using M = typename Lanes<T>::M;
  using I = typename Lanes<T>::I;
  const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t n_tiles = n_cams * tiles_x * tiles_y;
  const T* m2 = means2d.data_ptr<T>();
  const T* cn = conics.data_ptr<T>();
  const T* op = opacities.data_ptr<T>();
  const int32_t* off = tile_offsets.data_ptr<int32_t>();
  const int32_t* pg = pair_gauss.data_ptr<int32_t>();
  T* ot = out_t.data_ptr<T>();
  int32_t* oe = out_end.data_ptr<int32_t>();
  const Footprints<T> foot(cn, op, means2d.size(0));

#pragma omp parallel num_threads(num_threads())
  {
    auto sink = make_sink();
    std::vector<Splat<T>> splats;
    // per row of lanes: transmittance, still compositing (mask), one past the last splat
    V trans[kTile];
    M live[kTile], last[kTile];
    bool row_live[kTile];
#pragma omp for schedule(dynamic, 2)
    for (int64_t tile = 0; tile < n_tiles; ++tile) {
      const int64_t begin = off[tile], end = off[tile + 1];
      if (begin == end) continue;
      const TileOrigin o(tile, tiles_x, tiles_y, width, height);
      gather_tile(m2, cn, op, foot, pg, begin, end, o.y0, o.last_y, splats);
      sink.begin(tile);
      V fx;
      M inside;
      for (int l = 0; l < kTile; ++l) {
        fx[l] = T(o.x0 + l) + T(0.5);
        inside[l] = l <= o.last_x ? -1 : 0;
      }
      int32_t rows_live = o.last_y + 1;
      for (int r = 0; r < kTile; ++r) {
        trans[r] = V{} + T(1);
        last[r] = M{} + static_cast<I>(begin);
        live[r] = inside;
        row_live[r] = r < rows_live;
      }
      for (int64_t k = begin; k < end && rows_live > 0; ++k) {
        const Splat<T>& s = splats[k - begin];
        for (int32_t r = s.row_lo; r <= s.row_hi; ++r) {
          if (!row_live[r]) continue;
          const V dx = s.mx - fx, dy = V{} + (s.my - (T(o.y0 + r) + T(0.5)));
          const V power = power_lanes(s, dx, dy);
          const M hit = live[r] & (power <= T(0)) & (power >= s.log_min);
          const V clipped = power > T(0) ? V{} : (power < s.log_min ? V{} + s.log_min : power);
          const V raw = s.opacity * exp_lanes(clipped);
          const V alpha = hit ? (raw < Rules<T>::alpha_max ? raw : V{} + Rules<T>::alpha_max) : V{};
          const V next_t = trans[r] * (T(1) - alpha);
          const M stop = next_t < Rules<T>::transmittance_min;  // only a hit can bring it below
          const M use = hit & ~stop;
          sink.add(r, k, use ? alpha * trans[r] : V{});
          trans[r] = use ? next_t : trans[r];
          last[r] = use ? M{} + static_cast<I>(k + 1) : last[r];
          if (any_lane(stop)) {
            live[r] &= ~stop;
            if (!any_lane(live[r])) {
              row_live[r] = false;
              --rows_live;
            }
          }
        }
      }
      sink.end(o);
      for (int32_t r = 0; r <= o.last_y; ++r) {
        for (int32_t l = 0; l <= o.last_x; ++l) {
          const int64_t pix = o.pixel(width, height, r, l);
          ot[pix] = trans[r][l];
          oe[pix] = static_cast<int32_t>(last[r][l]);
        }
      }
    }
  }
}

// forward()'s sink: sums w * colour per pixel and writes the tile's colours.
template <typename T, int NC>
struct ColourSink {
  using V = typename Lanes<T>::V;
  const T* col;
  const int32_t* pg;
  int64_t C, width, height;
  T* oc;
  V acc[kTile][kMaxChannels];

  void begin(int64_t) {
    for (int r = 0; r < kTile; ++r)
      for (int64_t ch = 0; ch < C; ++ch) acc[r][ch] = V{};
  }
  void add(int32_t r, int64_t k, V w) {
    const T* c = col + static_cast<int64_t>(pg[k]) * C;
    for (int64_t ch = 0; ch < C; ++ch) acc[r][ch] += w * c[ch];
  }
  void end(const TileOrigin& o) {
    for (int32_t r = 0; r <= o.last_y; ++r)
      for (int32_t l = 0; l <= o.last_x; ++l) {
        const int64_t pix = o.pixel(width, height, r, l);
        for (int64_t ch = 0; ch < C; ++ch) oc[pix * C + ch] = acc[r][ch][l];
      }
  }
};

template <typename T, int NC>
void forward_impl(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& colors,
                  const torch::Tensor& opacities, const torch::Tensor& tile_offsets, const torch::Tensor& pair_gauss,
                  int64_t n_cams, int64_t width, int64_t height, torch::Tensor& out_color, torch::Tensor& out_t,
                  torch::Tensor& out_end) {
  const int64_t C = NC > 0 ? NC : colors.size(1);
  const T* col = colors.data_ptr<T>();
  const int32_t* pg = pair_gauss.data_ptr<int32_t>();
  T* oc = out_color.data_ptr<T>();
  sweep<T>(means2d, conics, opacities, tile_offsets, pair_gauss, n_cams, width, height, out_t, out_end,
           [&] { return ColourSink<T, NC>{col, pg, C, width, height, oc, {}}; });
}

// One recorded contribution: the pixel (within its tile: row * 8 + lane), the entry, its weight.
template <typename T>
struct Contribution {
  int32_t lane;
  int32_t entry;
  T weight;
};

// contributions()'s sink: keeps each tile's non-zero weights, in depth order, for the CSR assembly.
template <typename T>
struct RecordSink {
  using V = typename Lanes<T>::V;
  const int32_t* pg;
  std::vector<std::vector<Contribution<T>>>* tiles;
  std::vector<Contribution<T>> current;

  int64_t tile = 0;

  void begin(int64_t t) {
    tile = t;
    current.clear();
  }
  void add(int32_t r, int64_t k, V w) {  // a used lane's weight is > 0: alpha >= 1/255 and T >= 1e-4
    for (int l = 0; l < kTile; ++l)
      if (w[l] != T(0)) current.push_back({r * kTile + l, pg[k], w[l]});
  }
  void end(const TileOrigin&) { (*tiles)[tile] = current; }
};

// Per pixel, the compositing weights the sweep records, as CSR over the pixels (B*H*W rows, in image order;
// each row's entries front to back): (offsets int64, entries int32, weights, final transmittance).
template <typename T>
std::vector<torch::Tensor> contributions_impl(const torch::Tensor& means2d, const torch::Tensor& conics,
                                              const torch::Tensor& opacities, const torch::Tensor& tile_offsets,
                                              const torch::Tensor& pair_gauss, int64_t n_cams, int64_t width,
                                              int64_t height) {
  const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t n_tiles = n_cams * tiles_x * tiles_y, n_pixels = n_cams * height * width;
  auto out_t = torch::ones({n_cams, height, width}, means2d.options());
  auto out_end = torch::zeros({n_cams, height, width}, torch::dtype(torch::kInt32));
  std::vector<std::vector<Contribution<T>>> tiles(n_tiles);
  const int32_t* pg = pair_gauss.data_ptr<int32_t>();
  sweep<T>(means2d, conics, opacities, tile_offsets, pair_gauss, n_cams, width, height, out_t, out_end,
           [&] { return RecordSink<T>{pg, &tiles, {}}; });
  auto offsets = torch::zeros({n_pixels + 1}, torch::dtype(torch::kInt64));
  int64_t* row = offsets.data_ptr<int64_t>();
  auto pixel_of = [&](int64_t tile, int32_t lane) {
    return TileOrigin(tile, tiles_x, tiles_y, width, height).pixel(width, height, lane / kTile, lane % kTile);
  };
#pragma omp parallel for num_threads(num_threads()) schedule(dynamic, 8)
  for (int64_t t = 0; t < n_tiles; ++t)  // a pixel belongs to one tile: no two threads count it
    for (const auto& c : tiles[t]) ++row[pixel_of(t, c.lane) + 1];
  for (int64_t p = 0; p < n_pixels; ++p) row[p + 1] += row[p];
  auto entries = torch::empty({row[n_pixels]}, torch::dtype(torch::kInt32));
  auto weights = torch::empty({row[n_pixels]}, means2d.options());
  int32_t* ent = entries.data_ptr<int32_t>();
  T* wt = weights.data_ptr<T>();
  std::vector<int64_t> cursor(row, row + n_pixels);
#pragma omp parallel for num_threads(num_threads()) schedule(dynamic, 8)
  for (int64_t t = 0; t < n_tiles; ++t) {
    for (const auto& c : tiles[t]) {
      const int64_t slot = cursor[pixel_of(t, c.lane)]++;
      ent[slot] = c.entry;
      wt[slot] = c.weight;
    }
    std::vector<Contribution<T>>().swap(tiles[t]);
  }
  return {offsets, entries, weights, out_t};
}

// GEOM false: a colour-only step (nothing upstream trains means, conics or opacities): only the colour
// gradients are computed, the record's other columns stay zero.
template <typename T, int NC, bool GEOM>
torch::Tensor backward_impl(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& colors,
                            const torch::Tensor& opacities, const torch::Tensor& tile_offsets,
                            const torch::Tensor& pair_gauss, const torch::Tensor& final_t,
                            const torch::Tensor& pixel_end, const torch::Tensor& grad_color,
                            const torch::Tensor& grad_alpha, int64_t n_cams, int64_t width, int64_t height) {
  using V = typename Lanes<T>::V;
  using M = typename Lanes<T>::M;
  using I = typename Lanes<T>::I;
  const int64_t M_entries = means2d.size(0), C = NC > 0 ? NC : colors.size(1);
  const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t n_tiles = n_cams * tiles_x * tiles_y;
  const int64_t stride = 6 + C;  // per-entry gradient record: mx, my, a, b, c, opacity, colours
  const int n_threads = num_threads();
  auto buffers = torch::zeros({n_threads, M_entries, stride}, means2d.options());
  const T* m2 = means2d.data_ptr<T>();
  const T* cn = conics.data_ptr<T>();
  const T* col = colors.data_ptr<T>();
  const T* op = opacities.data_ptr<T>();
  const int32_t* off = tile_offsets.data_ptr<int32_t>();
  const int32_t* pg = pair_gauss.data_ptr<int32_t>();
  const T* ft = final_t.data_ptr<T>();
  const int32_t* pe = pixel_end.data_ptr<int32_t>();
  const T* gc = grad_color.data_ptr<T>();
  const T* ga = grad_alpha.data_ptr<T>();
  T* buf = buffers.data_ptr<T>();
  const Footprints<T> foot(cn, op, M_entries);

#pragma omp parallel num_threads(n_threads)
  {
    std::vector<Splat<T>> splats;
    T* mine = buf + static_cast<int64_t>(omp_get_thread_num()) * M_entries * stride;
    // per row of lanes: transmittance in front of the current splat, final transmittance, d loss /
    // d alpha_out, one past the last splat, colour gradient and the sum over later contributors of
    // w_j * c_j; rec: the current splat's gradient record, per lane, summed over rows
    V trans[kTile], t_final[kTile], g_alpha[kTile], grad[kTile][kMaxChannels];
    M stop[kTile];
    V behind[kTile][kMaxChannels], rec[6 + kMaxChannels];
    int32_t row_end[kTile];
#pragma omp for schedule(static, 2)  // fixed tile -> thread map: gradient sums are reproducible
    for (int64_t tile = 0; tile < n_tiles; ++tile) {
      const int64_t begin = off[tile], end = off[tile + 1];
      if (begin == end) continue;
      const TileOrigin o(tile, tiles_x, tiles_y, width, height);
      gather_tile(m2, cn, op, foot, pg, begin, end, o.y0, o.last_y, splats);
      V fx;
      for (int l = 0; l < kTile; ++l) fx[l] = T(o.x0 + l) + T(0.5);
      int64_t last = begin;
      for (int32_t r = 0; r < kTile; ++r) {
        trans[r] = t_final[r] = V{} + T(1);
        g_alpha[r] = V{};
        stop[r] = M{} + static_cast<I>(begin);
        row_end[r] = static_cast<int32_t>(begin);
        for (int64_t ch = 0; ch < C; ++ch) grad[r][ch] = behind[r][ch] = V{};
        if (r > o.last_y) continue;
        for (int32_t l = 0; l <= o.last_x; ++l) {
          const int64_t pix = o.pixel(width, height, r, l);
          trans[r][l] = t_final[r][l] = ft[pix];
          g_alpha[r][l] = ga[pix];
          stop[r][l] = pe[pix];
          row_end[r] = std::max(row_end[r], pe[pix]);
          for (int64_t ch = 0; ch < C; ++ch) grad[r][ch][l] = gc[pix * C + ch];
        }
        last = std::max<int64_t>(last, row_end[r]);
      }
      for (int64_t k = last - 1; k >= begin; --k) {
        const Splat<T>& s = splats[k - begin];
        const T* c = col + static_cast<int64_t>(pg[k]) * C;
        bool touched = false;
        for (int32_t r = s.row_lo; r <= s.row_hi; ++r) {
          if (k >= row_end[r]) continue;
          const V dx = s.mx - fx, dy = V{} + (s.my - (T(o.y0 + r) + T(0.5)));
          const V power = power_lanes(s, dx, dy);
          const M hit = (M{} + static_cast<I>(k) < stop[r]) & (power <= T(0)) & (power >= s.log_min);
          if (!any_lane(hit)) continue;
          if (!touched) std::fill(rec, rec + stride, V{});
          touched = true;
          const V clipped = power > T(0) ? V{} : (power < s.log_min ? V{} + s.log_min : power);
          const V gauss = exp_lanes(clipped);
          const V raw = s.opacity * gauss;
          const V alpha = hit ? (raw < Rules<T>::alpha_max ? raw : V{} + Rules<T>::alpha_max) : V{};
          const V inv = T(1) / (T(1) - alpha);
          const V t = trans[r] * inv;  // transmittance in front of this splat (unchanged when not hit)
          trans[r] = t;
          const V w = alpha * t;
          if constexpr (!GEOM) {
            for (int64_t ch = 0; ch < C; ++ch) rec[6 + ch] += w * grad[r][ch];
            continue;
          }
          V d_alpha = g_alpha[r] * t_final[r] * inv;
          for (int64_t ch = 0; ch < C; ++ch) {
            const V g = grad[r][ch];
            rec[6 + ch] += w * g;
            d_alpha += g * (t * c[ch] - behind[r][ch] * inv);
            behind[r][ch] += w * c[ch];
          }
          // selects, not products with a mask: a lane that is not hit may hold huge offsets
          const M on = hit & (raw < Rules<T>::alpha_max);  // clamped: alpha ignores the parameters
          const V d_power = on ? d_alpha * alpha : V{};
          const V ex = on ? dx : V{}, ey = on ? dy : V{};
          rec[0] -= d_power * (s.a * ex + s.b * ey);
          rec[1] -= d_power * (s.c * ey + s.b * ex);
          rec[2] -= T(0.5) * d_power * ex * ex;
          rec[3] -= d_power * ex * ey;
          rec[4] -= T(0.5) * d_power * ey * ey;
          rec[5] += on ? d_alpha * gauss : V{};
        }
        if (!touched) continue;
        T* dst = mine + static_cast<int64_t>(pg[k]) * stride;
        for (int64_t j = GEOM ? 0 : 6; j < stride; ++j) {
          T sum = T(0);
          for (int l = 0; l < kTile; ++l) sum += rec[j][l];
          dst[j] += sum;
        }
      }
    }
  }
  return n_threads == 1 ? buffers[0] : buffers.sum(0);
}

}  // namespace

// Forward compositing. Returns (color (B,H,W,C), transmittance (B,H,W), end index (B,H,W) = one past
// the last pair each pixel processed, absolute into pair_gauss).
std::vector<torch::Tensor> forward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                   torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor pair_gauss,
                                   int64_t n_cams, int64_t width, int64_t height) {
  check_inputs(means2d, conics, colors, opacities);
  const auto opts = means2d.options();
  auto out_color = torch::zeros({n_cams, height, width, colors.size(1)}, opts);
  auto out_t = torch::ones({n_cams, height, width}, opts);
  auto out_end = torch::zeros({n_cams, height, width}, torch::dtype(torch::kInt32));
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "gt2gs_forward", [&] {
    dispatch_channels(colors.size(1), [&](auto channels) {
      forward_impl<scalar_t, decltype(channels)::value>(means2d, conics, colors, opacities, tile_offsets, pair_gauss,
                                                       n_cams, width, height, out_color, out_t, out_end);
    });
  });
  return {out_color, out_t, out_end};
}

// The weights forward() gives each entry at each pixel (w = alpha T, the colour-independent part of the
// composite: colour = sum w c), as CSR over the B*H*W pixels: (offsets, entries, weights, transmittance).
std::vector<torch::Tensor> contributions(torch::Tensor means2d, torch::Tensor conics, torch::Tensor opacities,
                                         torch::Tensor tile_offsets, torch::Tensor pair_gauss, int64_t n_cams,
                                         int64_t width, int64_t height) {
  check_inputs(means2d, conics, opacities.reshape({-1, 1}), opacities);
  std::vector<torch::Tensor> out;
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "gt2gs_contributions", [&] {
    out = contributions_impl<scalar_t>(means2d, conics, opacities, tile_offsets, pair_gauss, n_cams, width, height);
  });
  return out;
}

namespace {

template <typename T>
void weighted_rows_impl(const int64_t* row, const int32_t* ent, const T* w, const T* v, int64_t rows, int64_t C,
                        T* out) {
#pragma omp parallel for num_threads(num_threads()) schedule(static, 256)
  for (int64_t p = 0; p < rows; ++p) {
    T acc[kMaxChannels] = {};
    for (int64_t k = row[p]; k < row[p + 1]; ++k)
      for (int64_t ch = 0; ch < C; ++ch) acc[ch] += w[k] * v[static_cast<int64_t>(ent[k]) * C + ch];
    for (int64_t ch = 0; ch < C; ++ch) out[p * C + ch] = acc[ch];
  }
}

template <typename T>
void weighted_rows_backward_impl(const int64_t* row, const int32_t* ent, const T* w, const T* g, int64_t rows,
                                 int64_t C, int64_t n_values, int n_threads, T* buf) {
#pragma omp parallel num_threads(n_threads)
  {
    T* mine = buf + static_cast<int64_t>(omp_get_thread_num()) * n_values * C;
#pragma omp for schedule(static)
    for (int64_t p = 0; p < rows; ++p)
      for (int64_t k = row[p]; k < row[p + 1]; ++k)
        for (int64_t ch = 0; ch < C; ++ch) mine[static_cast<int64_t>(ent[k]) * C + ch] += w[k] * g[p * C + ch];
  }
}

void check_rows(const torch::Tensor& offsets, const torch::Tensor& entries, const torch::Tensor& weights,
                const torch::Tensor& values) {
  TORCH_CHECK(offsets.dtype() == torch::kInt64 && entries.dtype() == torch::kInt32, "offsets int64, entries int32");
  TORCH_CHECK(weights.dtype() == values.dtype() && values.dim() == 2, "weights and values (M,C) of one dtype");
  TORCH_CHECK(values.size(1) <= kMaxChannels, "at most 32 channels");
  for (const auto* t : {&offsets, &entries, &weights}) TORCH_CHECK(t->is_contiguous(), "inputs must be contiguous");
}

}  // namespace

// colour[p] = sum over row p of weights * values[entries]: a render from recorded contributions (the same
// sum, in the same order, as forward()'s).
torch::Tensor weighted_rows(torch::Tensor offsets, torch::Tensor entries, torch::Tensor weights, torch::Tensor values) {
  values = values.contiguous();
  check_rows(offsets, entries, weights, values);
  const int64_t rows = offsets.size(0) - 1, C = values.size(1);
  auto out = torch::empty({rows, C}, values.options());
  AT_DISPATCH_FLOATING_TYPES(values.scalar_type(), "gt2gs_weighted_rows", [&] {
    weighted_rows_impl<scalar_t>(offsets.data_ptr<int64_t>(), entries.data_ptr<int32_t>(), weights.data_ptr<scalar_t>(),
                                 values.data_ptr<scalar_t>(), rows, C, out.data_ptr<scalar_t>());
  });
  return out;
}

// Gradient of weighted_rows() w.r.t. the values: grad_values[e] = sum of weight * grad[row] over e's
// contributions (per-thread sums over fixed row ranges, then added: reproducible).
torch::Tensor weighted_rows_backward(torch::Tensor offsets, torch::Tensor entries, torch::Tensor weights,
                                     torch::Tensor grad, int64_t n_values) {
  grad = grad.to(weights.dtype()).contiguous();
  check_rows(offsets, entries, weights, grad);
  const int64_t rows = offsets.size(0) - 1, C = grad.size(1);
  const int n_threads = num_threads();
  auto buffers = torch::zeros({n_threads, n_values, C}, grad.options());
  AT_DISPATCH_FLOATING_TYPES(grad.scalar_type(), "gt2gs_weighted_rows_backward", [&] {
    weighted_rows_backward_impl<scalar_t>(offsets.data_ptr<int64_t>(), entries.data_ptr<int32_t>(),
                                          weights.data_ptr<scalar_t>(), grad.data_ptr<scalar_t>(), rows, C, n_values,
                                          n_threads, buffers.data_ptr<scalar_t>());
  });
  return n_threads == 1 ? buffers[0] : buffers.sum(0);
}

// Backward of forward(): gradients w.r.t. means2d, conics, colors and opacities given the gradients
// of the composited colour and of alpha = 1 - transmittance (without ``geometry`` only the colours',
// the others zero).
std::vector<torch::Tensor> backward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                    torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor pair_gauss,
                                    torch::Tensor final_t, torch::Tensor pixel_end, torch::Tensor grad_color,
                                    torch::Tensor grad_alpha, int64_t n_cams, int64_t width, int64_t height,
                                    bool geometry) {
  check_inputs(means2d, conics, colors, opacities);
  grad_color = grad_color.to(means2d.dtype()).contiguous();
  grad_alpha = grad_alpha.to(means2d.dtype()).contiguous();
  torch::Tensor total;
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "gt2gs_backward", [&] {
    dispatch_channels(colors.size(1), [&](auto channels) {
      constexpr int nc = decltype(channels)::value;
      const auto run = geometry ? backward_impl<scalar_t, nc, true> : backward_impl<scalar_t, nc, false>;
      total = run(means2d, conics, colors, opacities, tile_offsets, pair_gauss, final_t, pixel_end, grad_color,
                  grad_alpha, n_cams, width, height);
    });
  });
  const int64_t M = means2d.size(0), C = colors.size(1);
  return {total.narrow(1, 0, 2).contiguous(), total.narrow(1, 2, 3).contiguous(), total.narrow(1, 6, C).contiguous(),
          total.narrow(1, 5, 1).reshape({M}).contiguous()};
}

// Defined in project_cpu.cpp.
std::vector<torch::Tensor> project_forward(torch::Tensor means, torch::Tensor quats, torch::Tensor scales,
                                           torch::Tensor opacities, torch::Tensor sh, torch::Tensor viewmats,
                                           torch::Tensor ks, int64_t width, int64_t height, double near, double far,
                                           int64_t sh_degree);
std::vector<torch::Tensor> project_backward(torch::Tensor means, torch::Tensor quats, torch::Tensor scales,
                                            torch::Tensor sh, torch::Tensor viewmats, torch::Tensor ks,
                                            int64_t width, int64_t height, int64_t sh_degree, torch::Tensor cam_ids,
                                            torch::Tensor gauss_ids, torch::Tensor g_means2d, torch::Tensor g_conics,
                                            torch::Tensor g_rgb, torch::Tensor g_depth, bool geometry);

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("project_forward", &project_forward, "Project Gaussians into cameras");
  m.def("project_backward", &project_backward, "Gradients of project_forward()");
  m.def("depth_order", &depth_order, "Entry indices front to back (stable radix sort of float32 depths)");
  m.def("bin_tiles", &bin_tiles, "Sort Gaussian/tile pairs by tile, front to back");
  m.def("forward", &forward, "Composite Gaussians over 8x8 tiles");
  m.def("backward", &backward, "Gradients of forward()");
  m.def("contributions", &contributions, "Per-pixel compositing weights of forward(), as CSR");
  m.def("weighted_rows", &weighted_rows, "Per row, the weighted sum of the rows' values");
  m.def("weighted_rows_backward", &weighted_rows_backward, "Gradient of weighted_rows() w.r.t. the values");
}
