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
constexpr float kAlphaMin = 1.0f / 255.0f;
constexpr float kAlphaMax = 0.99f;
constexpr float kTransmittanceMin = 1e-4f;

struct Splat {
  float mx, my, a, b, c, opacity, log_min;  // log_min: power below which alpha < 1/255
};

// Power of the Gaussian at a pixel centre; the same expression in forward and backward so that
// both make the same skip decisions.
inline float splat_power(const Splat& s, float px, float py, float& dx, float& dy) {
  dx = s.mx - px;
  dy = s.my - py;
  return -0.5f * (s.a * dx * dx + s.c * dy * dy) - s.b * dx * dy;
}

int num_threads() { return std::max(1, at::get_num_threads()); }

void check_inputs(const torch::Tensor& means2d, const torch::Tensor& conics, const torch::Tensor& colors,
                  const torch::Tensor& opacities) {
  TORCH_CHECK(means2d.dtype() == torch::kFloat32 && means2d.is_contiguous() && means2d.dim() == 2,
              "means2d must be contiguous float32 (M,2)");
  TORCH_CHECK(conics.dtype() == torch::kFloat32 && conics.is_contiguous(), "conics must be contiguous float32 (M,3)");
  TORCH_CHECK(colors.dtype() == torch::kFloat32 && colors.is_contiguous() && colors.dim() == 2,
              "colors must be contiguous float32 (M,C)");
  TORCH_CHECK(colors.size(1) >= 1 && colors.size(1) <= kMaxChannels, "colors must have 1..32 channels");
  TORCH_CHECK(opacities.dtype() == torch::kFloat32 && opacities.is_contiguous(), "opacities must be float32 (M,)");
}

// Gathers the splats of one tile's list into a contiguous local buffer (cache friendly).
void gather_tile(const float* means2d, const float* conics, const float* opacities, const int32_t* pair_gauss,
                 int64_t begin, int64_t end, std::vector<Splat>& out) {
  out.resize(end - begin);
  for (int64_t k = begin; k < end; ++k) {
    const int32_t g = pair_gauss[k];
    const float o = opacities[g];
    out[k - begin] = Splat{means2d[2 * g], means2d[2 * g + 1], conics[3 * g], conics[3 * g + 1], conics[3 * g + 2],
                           o, -std::log(255.0f * o)};
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

// Forward compositing. Returns (color (B,H,W,C), transmittance (B,H,W), end index (B,H,W) = one past
// the last pair each pixel processed, absolute into pair_gauss).
std::vector<torch::Tensor> forward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                   torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor pair_gauss,
                                   int64_t n_cams, int64_t width, int64_t height) {
  check_inputs(means2d, conics, colors, opacities);
  const int64_t C = colors.size(1);
  const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t n_tiles = n_cams * tiles_x * tiles_y;
  auto out_color = torch::zeros({n_cams, height, width, C}, torch::dtype(torch::kFloat32));
  auto out_t = torch::ones({n_cams, height, width}, torch::dtype(torch::kFloat32));
  auto out_end = torch::zeros({n_cams, height, width}, torch::dtype(torch::kInt32));
  const float* m2 = means2d.data_ptr<float>();
  const float* cn = conics.data_ptr<float>();
  const float* col = colors.data_ptr<float>();
  const float* op = opacities.data_ptr<float>();
  const int32_t* off = tile_offsets.data_ptr<int32_t>();
  const int32_t* pg = pair_gauss.data_ptr<int32_t>();
  float* oc = out_color.data_ptr<float>();
  float* ot = out_t.data_ptr<float>();
  int32_t* oe = out_end.data_ptr<int32_t>();

#pragma omp parallel num_threads(num_threads())
  {
    std::vector<Splat> splats;
#pragma omp for schedule(dynamic, 2)
    for (int64_t tile = 0; tile < n_tiles; ++tile) {
      const int64_t begin = off[tile], end = off[tile + 1];
      const int64_t cam = tile / (tiles_x * tiles_y), local = tile % (tiles_x * tiles_y);
      const int64_t x0 = (local % tiles_x) * kTile, y0 = (local / tiles_x) * kTile;
      gather_tile(m2, cn, op, pg, begin, end, splats);
      for (int64_t py = y0; py < std::min(y0 + kTile, height); ++py) {
        for (int64_t px = x0; px < std::min(x0 + kTile, width); ++px) {
          const float fx = px + 0.5f, fy = py + 0.5f;
          float acc[kMaxChannels] = {0.0f};
          float T = 1.0f;
          int64_t last = begin;
          for (int64_t k = begin; k < end; ++k) {
            const Splat& s = splats[k - begin];
            float dx, dy;
            const float power = splat_power(s, fx, fy, dx, dy);
            if (power > 0.0f || power < s.log_min) continue;
            const float alpha = std::min(kAlphaMax, s.opacity * std::exp(power));
            const float next_t = T * (1.0f - alpha);
            if (next_t < kTransmittanceMin) break;
            const float w = alpha * T;
            const float* c = col + pg[k] * C;
            for (int64_t ch = 0; ch < C; ++ch) acc[ch] += w * c[ch];
            T = next_t;
            last = k + 1;
          }
          const int64_t pix = (cam * height + py) * width + px;
          for (int64_t ch = 0; ch < C; ++ch) oc[pix * C + ch] = acc[ch];
          ot[pix] = T;
          oe[pix] = static_cast<int32_t>(last);
        }
      }
    }
  }
  return {out_color, out_t, out_end};
}

// Backward of forward(): gradients w.r.t. means2d, conics, colors and opacities given the gradients
// of the composited colour and of alpha = 1 - transmittance.
std::vector<torch::Tensor> backward(torch::Tensor means2d, torch::Tensor conics, torch::Tensor colors,
                                    torch::Tensor opacities, torch::Tensor tile_offsets, torch::Tensor pair_gauss,
                                    torch::Tensor final_t, torch::Tensor pixel_end, torch::Tensor grad_color,
                                    torch::Tensor grad_alpha, int64_t n_cams, int64_t width, int64_t height) {
  check_inputs(means2d, conics, colors, opacities);
  grad_color = grad_color.contiguous();
  grad_alpha = grad_alpha.contiguous();
  const int64_t M = means2d.size(0), C = colors.size(1);
  const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const int64_t n_tiles = n_cams * tiles_x * tiles_y;
  const int64_t stride = 6 + C;  // per-entry gradient record: mx, my, a, b, c, opacity, colours
  const int n_threads = num_threads();
  auto buffers = torch::zeros({n_threads, M, stride}, torch::dtype(torch::kFloat32));
  const float* m2 = means2d.data_ptr<float>();
  const float* cn = conics.data_ptr<float>();
  const float* col = colors.data_ptr<float>();
  const float* op = opacities.data_ptr<float>();
  const int32_t* off = tile_offsets.data_ptr<int32_t>();
  const int32_t* pg = pair_gauss.data_ptr<int32_t>();
  const float* ft = final_t.data_ptr<float>();
  const int32_t* pe = pixel_end.data_ptr<int32_t>();
  const float* gc = grad_color.data_ptr<float>();
  const float* ga = grad_alpha.data_ptr<float>();
  float* buf = buffers.data_ptr<float>();

#pragma omp parallel num_threads(n_threads)
  {
    std::vector<Splat> splats;
    std::vector<float> local;  // per-pair gradient records of the current tile
    float* mine = buf + static_cast<int64_t>(omp_get_thread_num()) * M * stride;
#pragma omp for schedule(dynamic, 2)
    for (int64_t tile = 0; tile < n_tiles; ++tile) {
      const int64_t begin = off[tile], end = off[tile + 1];
      if (begin == end) continue;
      const int64_t cam = tile / (tiles_x * tiles_y), loc = tile % (tiles_x * tiles_y);
      const int64_t x0 = (loc % tiles_x) * kTile, y0 = (loc / tiles_x) * kTile;
      gather_tile(m2, cn, op, pg, begin, end, splats);
      local.assign((end - begin) * stride, 0.0f);
      for (int64_t py = y0; py < std::min(y0 + kTile, height); ++py) {
        for (int64_t px = x0; px < std::min(x0 + kTile, width); ++px) {
          const int64_t pix = (cam * height + py) * width + px;
          const float fx = px + 0.5f, fy = py + 0.5f;
          const float t_final = ft[pix];
          const float* g = gc + pix * C;
          const float g_alpha_out = ga[pix];
          float behind[kMaxChannels] = {0.0f};  // sum over later contributors of w_j * c_j
          float T = t_final;
          for (int64_t k = pe[pix] - 1; k >= begin; --k) {
            const Splat& s = splats[k - begin];
            float dx, dy;
            const float power = splat_power(s, fx, fy, dx, dy);
            if (power > 0.0f || power < s.log_min) continue;
            const float gauss = std::exp(power);
            const float raw_alpha = s.opacity * gauss;
            const float alpha = std::min(kAlphaMax, raw_alpha);
            const float inv = 1.0f / (1.0f - alpha);
            T *= inv;  // transmittance in front of this Gaussian
            const float w = alpha * T;
            const float* c = col + pg[k] * C;
            float* rec = local.data() + (k - begin) * stride;
            float d_alpha = g_alpha_out * t_final * inv;
            for (int64_t ch = 0; ch < C; ++ch) {
              rec[6 + ch] += w * g[ch];
              d_alpha += g[ch] * (T * c[ch] - behind[ch] * inv);
              behind[ch] += w * c[ch];
            }
            if (raw_alpha >= kAlphaMax) continue;  // clamped: alpha does not depend on the parameters
            const float d_power = d_alpha * alpha;
            rec[0] += -d_power * (s.a * dx + s.b * dy);
            rec[1] += -d_power * (s.c * dy + s.b * dx);
            rec[2] += -0.5f * d_power * dx * dx;
            rec[3] += -d_power * dx * dy;
            rec[4] += -0.5f * d_power * dy * dy;
            rec[5] += d_alpha * gauss;
          }
        }
      }
      for (int64_t k = begin; k < end; ++k) {
        float* dst = mine + static_cast<int64_t>(pg[k]) * stride;
        const float* rec = local.data() + (k - begin) * stride;
        for (int64_t j = 0; j < stride; ++j) dst[j] += rec[j];
      }
    }
  }
  auto total = n_threads == 1 ? buffers[0] : buffers.sum(0);
  return {total.narrow(1, 0, 2).contiguous(), total.narrow(1, 2, 3).contiguous(), total.narrow(1, 6, C).contiguous(),
          total.narrow(1, 5, 1).reshape({M}).contiguous()};
}

PYBIND11_MODULE(TORCH_EXTENSION_NAME, m) {
  m.def("bin_tiles", &bin_tiles, "Sort Gaussian/tile pairs by tile, front to back");
  m.def("forward", &forward, "Composite Gaussians over 8x8 tiles");
  m.def("backward", &backward, "Gradients of forward()");
}
