// Tile-based Gaussian compositing on the CPU (OpenMP over 8x8 tiles), forward and backward.
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
#include <vector>

namespace {

constexpr int kTile = 8;
constexpr int kTilePixels = kTile * kTile;
constexpr int kMaxChannels = 32;

template <typename T>
struct Rules {  // the alpha rules in the kernel's precision
  static constexpr T alpha_max = T(0.99);
  static constexpr T transmittance_min = T(1e-4);
};

template <typename T>
struct Splat {
  T mx, my, a, b, c, opacity, log_min;  // log_min: power below which alpha < 1/255
};

// Power of the Gaussian at a pixel centre; the same expression in forward and backward so that
// both make the same skip decisions.
template <typename T>
inline T splat_power(const Splat<T>& s, T px, T py, T& dx, T& dy) {
  dx = s.mx - px;
  dy = s.my - py;
  return T(-0.5) * (s.a * dx * dx + s.c * dy * dy) - s.b * dx * dy;
}

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

// Gathers the splats of one tile's list into a contiguous local buffer (cache friendly).
template <typename T>
void gather_tile(const T* means2d, const T* conics, const T* opacities, const int32_t* pair_gauss,
                 int64_t begin, int64_t end, std::vector<Splat<T>>& out) {
  out.resize(end - begin);
  for (int64_t k = begin; k < end; ++k) {
    const int32_t g = pair_gauss[k];
    const T o = opacities[g];
    out[k - begin] = Splat<T>{means2d[2 * g], means2d[2 * g + 1], conics[3 * g], conics[3 * g + 1],
                              conics[3 * g + 2], o, -std::log(T(255) * o)};
  }
}

}  // namespace

// Counting sort of (entry, tile) pairs by tile; entries are visited in the given depth order, so
// each tile's list comes out sorted front to back. Returns (tile_offsets[n_tiles+1], pair_gauss[P]).
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

  auto offsets = torch::zeros({n_tiles + 1}, torch::dtype(torch::kInt32));
  int32_t* off = offsets.data_ptr<int32_t>();
  for (int64_t i = 0; i < m; ++i) {
    const int32_t* b = bb + 4 * i;
    const int64_t base = cam[i] * tiles_per_cam;
    for (int32_t ty = b[1]; ty <= b[3]; ++ty)
      for (int32_t tx = b[0]; tx <= b[2]; ++tx) off[base + ty * tiles_x + tx + 1] += 1;
  }
  int64_t total = 0;
  for (int64_t t = 1; t <= n_tiles; ++t) {
    total += off[t];
    TORCH_CHECK(total < INT32_MAX, "too many Gaussian/tile pairs for one render; render fewer cameras at once");
    off[t] = static_cast<int32_t>(total);
  }
  auto pairs = torch::empty({total}, torch::dtype(torch::kInt32));
  int32_t* pg = pairs.data_ptr<int32_t>();
  std::vector<int32_t> cursor(off, off + n_tiles);
  for (int64_t r = 0; r < m; ++r) {
    const int64_t i = order[r];
    const int32_t* b = bb + 4 * i;
    const int64_t base = cam[i] * tiles_per_cam;
    for (int32_t ty = b[1]; ty <= b[3]; ++ty)
      for (int32_t tx = b[0]; tx <= b[2]; ++tx) pg[cursor[base + ty * tiles_x + tx]++] = static_cast<int32_t>(i);
  }
  return {offsets, pairs};
}

namespace {

template <typename T>
void forward_impl(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& colors,
                  const torch::Tensor& opacities, const torch::Tensor& tile_offsets, const torch::Tensor& pair_gauss,
                  int64_t n_cams, int64_t width, int64_t height, torch::Tensor& out_color, torch::Tensor& out_t,
                  torch::Tensor& out_end) {
  const int64_t C = colors.size(1);
  const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t n_tiles = n_cams * tiles_x * tiles_y;
  const T* m2 = means2d.data_ptr<T>();
  const T* cn = conics.data_ptr<T>();
  const T* col = colors.data_ptr<T>();
  const T* op = opacities.data_ptr<T>();
  const int32_t* off = tile_offsets.data_ptr<int32_t>();
  const int32_t* pg = pair_gauss.data_ptr<int32_t>();
  T* oc = out_color.data_ptr<T>();
  T* ot = out_t.data_ptr<T>();
  int32_t* oe = out_end.data_ptr<int32_t>();

#pragma omp parallel num_threads(num_threads())
  {
    std::vector<Splat<T>> splats;
#pragma omp for schedule(dynamic, 2)
    for (int64_t tile = 0; tile < n_tiles; ++tile) {
      const int64_t begin = off[tile], end = off[tile + 1];
      if (begin == end) continue;
      const int64_t cam = tile / (tiles_x * tiles_y), local = tile % (tiles_x * tiles_y);
      const int64_t x0 = (local % tiles_x) * kTile, y0 = (local / tiles_x) * kTile;
      gather_tile(m2, cn, op, pg, begin, end, splats);
      for (int64_t py = y0; py < std::min(y0 + kTile, height); ++py) {
        for (int64_t px = x0; px < std::min(x0 + kTile, width); ++px) {
          const T fx = T(px) + T(0.5), fy = T(py) + T(0.5);
          T acc[kMaxChannels] = {T(0)};
          T trans = T(1);
          int64_t last = begin;
          for (int64_t k = begin; k < end; ++k) {
            const Splat<T>& s = splats[k - begin];
            T dx, dy;
            const T power = splat_power(s, fx, fy, dx, dy);
            if (power > T(0) || power < s.log_min) continue;
            const T alpha = std::min(Rules<T>::alpha_max, s.opacity * std::exp(power));
            const T next_t = trans * (T(1) - alpha);
            if (next_t < Rules<T>::transmittance_min) break;
            const T w = alpha * trans;
            const T* c = col + pg[k] * C;
            for (int64_t ch = 0; ch < C; ++ch) acc[ch] += w * c[ch];
            trans = next_t;
            last = k + 1;
          }
          const int64_t pix = (cam * height + py) * width + px;
          for (int64_t ch = 0; ch < C; ++ch) oc[pix * C + ch] = acc[ch];
          ot[pix] = trans;
          oe[pix] = static_cast<int32_t>(last);
        }
      }
    }
  }
}

template <typename T>
torch::Tensor backward_impl(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& colors,
                            const torch::Tensor& opacities, const torch::Tensor& tile_offsets,
                            const torch::Tensor& pair_gauss, const torch::Tensor& final_t,
                            const torch::Tensor& pixel_end, const torch::Tensor& grad_color,
                            const torch::Tensor& grad_alpha, int64_t n_cams, int64_t width, int64_t height) {
  const int64_t M = means2d.size(0), C = colors.size(1);
  const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t n_tiles = n_cams * tiles_x * tiles_y;
  const int64_t stride = 6 + C;  // per-entry gradient record: mx, my, a, b, c, opacity, colours
  const int n_threads = num_threads();
  auto buffers = torch::zeros({n_threads, M, stride}, means2d.options());
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

#pragma omp parallel num_threads(n_threads)
  {
    std::vector<Splat<T>> splats;
    std::vector<T> local;  // per-pair gradient records of the current tile
    T* mine = buf + static_cast<int64_t>(omp_get_thread_num()) * M * stride;
#pragma omp for schedule(static, 2)  // fixed tile -> thread map: gradient sums are reproducible
    for (int64_t tile = 0; tile < n_tiles; ++tile) {
      const int64_t begin = off[tile], end = off[tile + 1];
      if (begin == end) continue;
      const int64_t cam = tile / (tiles_x * tiles_y), loc = tile % (tiles_x * tiles_y);
      const int64_t x0 = (loc % tiles_x) * kTile, y0 = (loc / tiles_x) * kTile;
      gather_tile(m2, cn, op, pg, begin, end, splats);
      local.assign((end - begin) * stride, T(0));
      for (int64_t py = y0; py < std::min(y0 + kTile, height); ++py) {
        for (int64_t px = x0; px < std::min(x0 + kTile, width); ++px) {
          const int64_t pix = (cam * height + py) * width + px;
          const T fx = T(px) + T(0.5), fy = T(py) + T(0.5);
          const T t_final = ft[pix];
          const T* g = gc + pix * C;
          const T g_alpha_out = ga[pix];
          T behind[kMaxChannels] = {T(0)};  // sum over later contributors of w_j * c_j
          T trans = t_final;
          for (int64_t k = pe[pix] - 1; k >= begin; --k) {
            const Splat<T>& s = splats[k - begin];
            T dx, dy;
            const T power = splat_power(s, fx, fy, dx, dy);
            if (power > T(0) || power < s.log_min) continue;
            const T gauss = std::exp(power);
            const T raw_alpha = s.opacity * gauss;
            const T alpha = std::min(Rules<T>::alpha_max, raw_alpha);
            const T inv = T(1) / (T(1) - alpha);
            trans *= inv;  // transmittance in front of this Gaussian
            const T w = alpha * trans;
            const T* c = col + pg[k] * C;
            T* rec = local.data() + (k - begin) * stride;
            T d_alpha = g_alpha_out * t_final * inv;
            for (int64_t ch = 0; ch < C; ++ch) {
              rec[6 + ch] += w * g[ch];
              d_alpha += g[ch] * (trans * c[ch] - behind[ch] * inv);
              behind[ch] += w * c[ch];
            }
            if (raw_alpha >= Rules<T>::alpha_max) continue;  // clamped: alpha ignores the parameters
            const T d_power = d_alpha * alpha;
            rec[0] -= d_power * (s.a * dx + s.b * dy);
            rec[1] -= d_power * (s.c * dy + s.b * dx);
            rec[2] -= T(0.5) * d_power * dx * dx;
            rec[3] -= d_power * dx * dy;
            rec[4] -= T(0.5) * d_power * dy * dy;
            rec[5] += d_alpha * gauss;
          }
        }
      }
      for (int64_t k = begin; k < end; ++k) {
        T* dst = mine + static_cast<int64_t>(pg[k]) * stride;
        const T* rec = local.data() + (k - begin) * stride;
        for (int64_t j = 0; j < stride; ++j) dst[j] += rec[j];
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
    forward_impl<scalar_t>(means2d, conics, colors, opacities, tile_offsets, pair_gauss, n_cams, width, height,
                           out_color, out_t, out_end);
  });
  return {out_color, out_t, out_end};
}

// Backward of forward(): gradients w.r.t. means2d, conics, colors and opacities given the gradients
// of the composited colour and of alpha = 1 - transmittance.
std::vector<torch::Tensor> backward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                    torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor pair_gauss,
                                    torch::Tensor final_t, torch::Tensor pixel_end, torch::Tensor grad_color,
                                    torch::Tensor grad_alpha, int64_t n_cams, int64_t width, int64_t height) {
  check_inputs(means2d, conics, colors, opacities);
  grad_color = grad_color.to(means2d.dtype()).contiguous();
  grad_alpha = grad_alpha.to(means2d.dtype()).contiguous();
  torch::Tensor total;
  AT_DISPATCH_FLOATING_TYPES(means2d.scalar_type(), "gt2gs_backward", [&] {
    total = backward_impl<scalar_t>(means2d, conics, colors, opacities, tile_offsets, pair_gauss, final_t,
                                    pixel_end, grad_color, grad_alpha, n_cams, width, height);
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
                                            torch::Tensor g_rgb, torch::Tensor g_depth);

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("project_forward", &project_forward, "Project Gaussians into cameras");
  m.def("project_backward", &project_backward, "Gradients of project_forward()");
  m.def("bin_tiles", &bin_tiles, "Sort Gaussian/tile pairs by tile, front to back");
  m.def("forward", &forward, "Composite Gaussians over 8x8 tiles");
  m.def("backward", &backward, "Gradients of forward()");
}
