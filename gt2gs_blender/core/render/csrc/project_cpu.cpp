// EWA projection of 3D Gaussians into pinhole cameras and its backward, on the CPU (OpenMP).
//
// The same mathematics as rasterizer/projection.py (which is the portable reference): camera
// transform, 3DGS's frustum-clamped Jacobian, 2D covariance + 0.3 px^2 dilation, conic, the
// alpha >= 1/255 footprint box, and real SH colours up to degree 3. Everything is computed in
// double (det = ac - b^2 cancels in float for needle-like Gaussians) and stored in the I/O dtype.
#include <torch/extension.h>

#include <algorithm>
#include <cmath>
#include <cstring>

namespace {

constexpr int kTile = 8;
constexpr double kEps2d = 0.3;
constexpr double kFovClamp = 1.3;
constexpr double kAlphaMin = 1.0 / 255.0;

constexpr double C0 = 0.28209479177387814;
constexpr double C1 = 0.4886025119029199;
constexpr double C2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
                          0.5462742152960396};
constexpr double C3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
                          -0.4570457994644658, 1.445305721320277, -0.5900435899266435};

struct Cam {
  double r[9], t[3], fx, fy, cx, cy, center[3], lim_xp, lim_xn, lim_yp, lim_yn;
};

template <typename T>
Cam camera(const T* viewmat, const T* k, int64_t width, int64_t height) {
  Cam c;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) c.r[3 * i + j] = viewmat[4 * i + j];
    c.t[i] = viewmat[4 * i + 3];
  }
  for (int j = 0; j < 3; ++j) c.center[j] = -(c.r[j] * c.t[0] + c.r[3 + j] * c.t[1] + c.r[6 + j] * c.t[2]);
  c.fx = k[0];
  c.fy = k[4];
  c.cx = k[2];
  c.cy = k[5];
  c.lim_xp = (width - c.cx) / c.fx + (kFovClamp - 1.0) * 0.5 * width / c.fx;
  c.lim_xn = c.cx / c.fx + (kFovClamp - 1.0) * 0.5 * width / c.fx;
  c.lim_yp = (height - c.cy) / c.fy + (kFovClamp - 1.0) * 0.5 * height / c.fy;
  c.lim_yn = c.cy / c.fy + (kFovClamp - 1.0) * 0.5 * height / c.fy;
  return c;
}

// Rotation matrix (row-major) of a quaternion (w, x, y, z); returns false for a zero quaternion.
bool rotation(const double q_in[4], double qn[4], double& norm, double r[9]) {
  norm = std::sqrt(q_in[0] * q_in[0] + q_in[1] * q_in[1] + q_in[2] * q_in[2] + q_in[3] * q_in[3]);
  const bool ok = norm > 1e-12;
  for (int i = 0; i < 4; ++i) qn[i] = ok ? q_in[i] / norm : (i == 0 ? 1.0 : 0.0);
  const double w = qn[0], x = qn[1], y = qn[2], z = qn[3];
  const double m[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                       2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                       2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)};
  std::copy(m, m + 9, r);
  return ok;
}

void sh_basis(const double d[3], int degree, double b[16]) {
  const double x = d[0], y = d[1], z = d[2];
  b[0] = C0;
  if (degree < 1) return;
  b[1] = -C1 * y;
  b[2] = C1 * z;
  b[3] = -C1 * x;
  if (degree < 2) return;
  const double xx = x * x, yy = y * y, zz = z * z;
  b[4] = C2[0] * x * y;
  b[5] = C2[1] * y * z;
  b[6] = C2[2] * (2 * zz - xx - yy);
  b[7] = C2[3] * x * z;
  b[8] = C2[4] * (xx - yy);
  if (degree < 3) return;
  b[9] = C3[0] * y * (3 * xx - yy);
  b[10] = C3[1] * x * y * z;
  b[11] = C3[2] * y * (4 * zz - xx - yy);
  b[12] = C3[3] * z * (2 * zz - 3 * xx - 3 * yy);
  b[13] = C3[4] * x * (4 * zz - xx - yy);
  b[14] = C3[5] * z * (xx - yy);
  b[15] = C3[6] * x * (xx - 3 * yy);
}

// Gradient of sum_k gb[k] * basis_k(d) with respect to the direction d.
void sh_basis_grad(const double d[3], int degree, const double gb[16], double g[3]) {
  const double x = d[0], y = d[1], z = d[2];
  g[0] = g[1] = g[2] = 0.0;
  if (degree < 1) return;
  g[1] += -C1 * gb[1];
  g[2] += C1 * gb[2];
  g[0] += -C1 * gb[3];
  if (degree < 2) return;
  const double xx = x * x, yy = y * y, zz = z * z;
  g[0] += C2[0] * y * gb[4];
  g[1] += C2[0] * x * gb[4];
  g[1] += C2[1] * z * gb[5];
  g[2] += C2[1] * y * gb[5];
  g[0] += -2 * C2[2] * x * gb[6];
  g[1] += -2 * C2[2] * y * gb[6];
  g[2] += 4 * C2[2] * z * gb[6];
  g[0] += C2[3] * z * gb[7];
  g[2] += C2[3] * x * gb[7];
  g[0] += 2 * C2[4] * x * gb[8];
  g[1] += -2 * C2[4] * y * gb[8];
  if (degree < 3) return;
  g[0] += C3[0] * 6 * x * y * gb[9];
  g[1] += C3[0] * (3 * xx - 3 * yy) * gb[9];
  g[0] += C3[1] * y * z * gb[10];
  g[1] += C3[1] * x * z * gb[10];
  g[2] += C3[1] * x * y * gb[10];
  g[0] += C3[2] * (-2 * x * y) * gb[11];
  g[1] += C3[2] * (4 * zz - xx - 3 * yy) * gb[11];
  g[2] += C3[2] * 8 * y * z * gb[11];
  g[0] += C3[3] * (-6 * x * z) * gb[12];
  g[1] += C3[3] * (-6 * y * z) * gb[12];
  g[2] += C3[3] * (6 * zz - 3 * xx - 3 * yy) * gb[12];
  g[0] += C3[4] * (4 * zz - 3 * xx - yy) * gb[13];
  g[1] += C3[4] * (-2 * x * y) * gb[13];
  g[2] += C3[4] * 8 * x * z * gb[13];
  g[0] += C3[5] * 2 * x * z * gb[14];
  g[1] += C3[5] * (-2 * y * z) * gb[14];
  g[2] += C3[5] * (xx - yy) * gb[14];
  g[0] += C3[6] * (3 * xx - 3 * yy) * gb[15];
  g[1] += C3[6] * (-6 * x * y) * gb[15];
}

// Everything the forward computes for one (camera, Gaussian) pair, kept for the backward.
struct Geometry {
  double p[3];        // camera-space mean
  double jac[6];      // 2x3 Jacobian (row-major)
  bool clamp_x, clamp_y;
  double tmat[6];     // J R (2x3)
  double rq[9];       // Gaussian rotation
  double qn[4], qnorm;
  bool q_ok;
  double sigma[9];    // world covariance
  double cov[3];      // dilated 2D covariance a, b, c
  double det;
};

template <typename T>
void geometry(const Cam& c, const T* mean, const T* quat, const T* scale, Geometry& g) {
  for (int i = 0; i < 3; ++i)
    g.p[i] = c.r[3 * i] * mean[0] + c.r[3 * i + 1] * mean[1] + c.r[3 * i + 2] * mean[2] + c.t[i];
  const double x = g.p[0], y = g.p[1], z = g.p[2];
  const double rx = x / z, ry = y / z;
  const double cx = std::min(std::max(rx, -c.lim_xn), c.lim_xp), cy = std::min(std::max(ry, -c.lim_yn), c.lim_yp);
  g.clamp_x = cx != rx;
  g.clamp_y = cy != ry;
  g.jac[0] = c.fx / z;
  g.jac[1] = 0.0;
  g.jac[2] = -c.fx * cx / z;
  g.jac[3] = 0.0;
  g.jac[4] = c.fy / z;
  g.jac[5] = -c.fy * cy / z;
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 3; ++j)
      g.tmat[3 * i + j] = g.jac[3 * i] * c.r[j] + g.jac[3 * i + 1] * c.r[3 + j] + g.jac[3 * i + 2] * c.r[6 + j];
  const double q[4] = {double(quat[0]), double(quat[1]), double(quat[2]), double(quat[3])};
  g.q_ok = rotation(q, g.qn, g.qnorm, g.rq);
  double m[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) m[3 * i + j] = g.rq[3 * i + j] * double(scale[j]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      g.sigma[3 * i + j] = m[3 * i] * m[3 * j] + m[3 * i + 1] * m[3 * j + 1] + m[3 * i + 2] * m[3 * j + 2];
  double ts[6];  // T Sigma
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 3; ++j)
      ts[3 * i + j] = g.tmat[3 * i] * g.sigma[j] + g.tmat[3 * i + 1] * g.sigma[3 + j] + g.tmat[3 * i + 2] * g.sigma[6 + j];
  const double a = ts[0] * g.tmat[0] + ts[1] * g.tmat[1] + ts[2] * g.tmat[2] + kEps2d;
  const double b = ts[0] * g.tmat[3] + ts[1] * g.tmat[4] + ts[2] * g.tmat[5];
  const double cc = ts[3] * g.tmat[3] + ts[4] * g.tmat[4] + ts[5] * g.tmat[5] + kEps2d;
  g.cov[0] = a;
  g.cov[1] = b;
  g.cov[2] = cc;
  g.det = a * cc - b * b;
}

void view_dir(const Cam& c, const double mean[3], double d[3], double& len) {
  for (int i = 0; i < 3; ++i) d[i] = mean[i] - c.center[i];
  len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const double inv = 1.0 / std::max(len, 1e-12);
  for (int i = 0; i < 3; ++i) d[i] *= inv;
}

template <typename T>
void project_forward_impl(const torch::Tensor& means, const torch::Tensor& quats, const torch::Tensor& scales,
                          const torch::Tensor& opacities, const torch::Tensor& sh, const torch::Tensor& viewmats,
                          const torch::Tensor& ks, int64_t width, int64_t height, double near, double far,
                          int64_t sh_degree, torch::Tensor& means2d, torch::Tensor& conics, torch::Tensor& rgb,
                          torch::Tensor& depth, torch::Tensor& radii, torch::Tensor& rects, torch::Tensor& valid) {
  const int64_t B = viewmats.size(0), N = means.size(0);
  const int64_t K = sh_degree >= 0 ? sh.size(1) : 0;
  const int64_t tiles_x = (width + kTile - 1) / kTile, tiles_y = (height + kTile - 1) / kTile;
  const T* mp = means.data_ptr<T>();
  const T* qp = quats.data_ptr<T>();
  const T* sp = scales.data_ptr<T>();
  const T* op = opacities.data_ptr<T>();
  const T* shp = sh_degree >= 0 ? sh.data_ptr<T>() : nullptr;
  T* o_m = means2d.data_ptr<T>();
  T* o_c = conics.data_ptr<T>();
  T* o_rgb = sh_degree >= 0 ? rgb.data_ptr<T>() : nullptr;
  T* o_d = depth.data_ptr<T>();
  T* o_r = radii.data_ptr<T>();
  int32_t* o_rect = rects.data_ptr<int32_t>();
  bool* o_v = valid.data_ptr<bool>();
  for (int64_t b = 0; b < B; ++b) {
    const Cam c = camera(viewmats.data_ptr<T>() + 16 * b, ks.data_ptr<T>() + 9 * b, width, height);
#pragma omp parallel for schedule(static) num_threads(std::max(1, at::get_num_threads()))
    for (int64_t n = 0; n < N; ++n) {
      const int64_t e = b * N + n;
      o_v[e] = false;
      const double o = op[n];
      if (!(o >= kAlphaMin)) continue;
      Geometry g;
      geometry(c, mp + 3 * n, qp + 4 * n, sp + 3 * n, g);
      const double z = g.p[2];
      if (!(z > near && z < far) || !(g.det > 0) || !std::isfinite(g.det)) continue;
      const double u = c.fx * g.p[0] / z + c.cx, v = c.fy * g.p[1] / z + c.cy;
      const double r2 = 2.0 * std::log(255.0 * o);
      const double rad_x = std::sqrt(r2 * g.cov[0]) * (1.0 + 1e-4) + 1e-3;
      const double rad_y = std::sqrt(r2 * g.cov[2]) * (1.0 + 1e-4) + 1e-3;
      if (!std::isfinite(u) || !std::isfinite(v) || !std::isfinite(rad_x) || !std::isfinite(rad_y)) continue;
      const double lo_x = std::max(0.0, std::ceil(u - rad_x - 0.5)), hi_x = std::min(double(width - 1), std::floor(u + rad_x - 0.5));
      const double lo_y = std::max(0.0, std::ceil(v - rad_y - 0.5)), hi_y = std::min(double(height - 1), std::floor(v + rad_y - 0.5));
      if (lo_x > hi_x || lo_y > hi_y) continue;
      int32_t* rect = o_rect + 4 * e;
      rect[0] = std::min<int32_t>(int32_t(lo_x) / kTile, int32_t(tiles_x - 1));
      rect[1] = std::min<int32_t>(int32_t(lo_y) / kTile, int32_t(tiles_y - 1));
      rect[2] = int32_t(hi_x) / kTile;
      rect[3] = int32_t(hi_y) / kTile;
      o_v[e] = true;
      o_m[2 * e] = T(u);
      o_m[2 * e + 1] = T(v);
      const double inv_det = 1.0 / g.det;
      o_c[3 * e] = T(g.cov[2] * inv_det);
      o_c[3 * e + 1] = T(-g.cov[1] * inv_det);
      o_c[3 * e + 2] = T(g.cov[0] * inv_det);
      o_d[e] = T(z);
      o_r[2 * e] = T(rad_x);
      o_r[2 * e + 1] = T(rad_y);
      if (sh_degree >= 0) {
        const double mean[3] = {double(mp[3 * n]), double(mp[3 * n + 1]), double(mp[3 * n + 2])};
        double d[3], len, basis[16];
        view_dir(c, mean, d, len);
        sh_basis(d, int(sh_degree), basis);
        const int64_t nb = (sh_degree + 1) * (sh_degree + 1);
        for (int ch = 0; ch < 3; ++ch) {
          double acc = 0.5;
          for (int64_t k = 0; k < nb; ++k) acc += basis[k] * double(shp[(n * K + k) * 3 + ch]);
          o_rgb[3 * e + ch] = T(std::max(acc, 0.0));
        }
      }
    }
  }
}

// The SH colour's backward for one entry: accumulates into the Gaussian's SH gradient and, when ``dmean``
// is given, the view direction's share of the mean's gradient (degree > 0).
template <typename T>
void sh_backward_entry(const Cam& c, const T* mean, const T* shc, int64_t K, int sh_degree, const T* g_rgb, T* gsh,
                       double* dmean) {
  const double m3[3] = {double(mean[0]), double(mean[1]), double(mean[2])};
  double d[3], len, basis[16], gb[16] = {0.0};
  view_dir(c, m3, d, len);
  sh_basis(d, sh_degree, basis);
  const int64_t nb = (sh_degree + 1) * (sh_degree + 1);
  for (int ch = 0; ch < 3; ++ch) {
    double acc = 0.5;
    for (int64_t k = 0; k < nb; ++k) acc += basis[k] * double(shc[k * 3 + ch]);
    if (acc < 0.0) continue;  // clamped channel
    const double gc = g_rgb[ch];
    for (int64_t k = 0; k < nb; ++k) {
      gsh[k * 3 + ch] += T(basis[k] * gc);
      gb[k] += double(shc[k * 3 + ch]) * gc;
    }
  }
  if (dmean != nullptr && sh_degree > 0 && len > 1e-12) {
    double gd[3];
    sh_basis_grad(d, sh_degree, gb, gd);
    const double dot = gd[0] * d[0] + gd[1] * d[1] + gd[2] * d[2];
    for (int i = 0; i < 3; ++i) dmean[i] += (gd[i] - d[i] * dot) / len;
  }
}

// Backward for one entry: accumulates into the Gaussian's gradient slots.
template <typename T>
void project_backward_entry(const Cam& c, const T* mean, const T* quat, const T* scale, const T* shc, int64_t K,
                            int sh_degree, const T* g_m2, const T* g_con, const T* g_rgb, double g_depth,
                            T* gm, T* gq, T* gs, T* gsh) {
  Geometry g;
  geometry(c, mean, quat, scale, g);
  const double x = g.p[0], y = g.p[1], z = g.p[2];
  double dp[3] = {0.0, 0.0, g_depth};
  // means2d
  const double gu = g_m2[0], gv = g_m2[1];
  dp[0] += gu * c.fx / z;
  dp[1] += gv * c.fy / z;
  dp[2] += -gu * c.fx * x / (z * z) - gv * c.fy * y / (z * z);
  // conic = inverse of cov2 -> gradient on cov2: -Q G Q with G the symmetric conic gradient
  const double inv_det = 1.0 / g.det;
  const double q00 = g.cov[2] * inv_det, q01 = -g.cov[1] * inv_det, q11 = g.cov[0] * inv_det;
  const double G00 = g_con[0], G01 = 0.5 * double(g_con[1]), G11 = g_con[2];
  const double qg00 = q00 * G00 + q01 * G01, qg01 = q00 * G01 + q01 * G11;
  const double qg10 = q01 * G00 + q11 * G01, qg11 = q01 * G01 + q11 * G11;
  const double dc00 = -(qg00 * q00 + qg01 * q01), dc01 = -(qg00 * q01 + qg01 * q11);
  const double dc11 = -(qg10 * q01 + qg11 * q11);
  const double gcov[4] = {dc00, dc01, dc01, dc11};  // d loss / d cov2 (symmetric, full)
  // cov2 = T Sigma T^T: dSigma = T^T Gc T, dT = 2 Gc T Sigma
  double dsigma[9], dt[6], gt[6];
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 3; ++j) gt[3 * i + j] = gcov[2 * i] * g.tmat[j] + gcov[2 * i + 1] * g.tmat[3 + j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dsigma[3 * i + j] = g.tmat[i] * gt[j] + g.tmat[3 + i] * gt[3 + j];
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 3; ++j)
      dt[3 * i + j] = 2.0 * (gt[3 * i] * g.sigma[j] + gt[3 * i + 1] * g.sigma[3 + j] + gt[3 * i + 2] * g.sigma[6 + j]);
  // T = J R: dJ = dT R^T
  double dj[6];
  for (int i = 0; i < 2; ++i)
    for (int j = 0; j < 3; ++j)
      dj[3 * i + j] = dt[3 * i] * c.r[3 * j] + dt[3 * i + 1] * c.r[3 * j + 1] + dt[3 * i + 2] * c.r[3 * j + 2];
  const double z2 = z * z, z3 = z2 * z;
  dp[2] += -dj[0] * c.fx / z2 - dj[4] * c.fy / z2;
  if (g.clamp_x) {
    dp[2] += dj[2] * c.fx * (-g.jac[2] / c.fx * z) / z2;  // J02 = -fx r / z with r fixed
  } else {
    dp[0] += -dj[2] * c.fx / z2;
    dp[2] += dj[2] * 2.0 * c.fx * x / z3;
  }
  if (g.clamp_y) {
    dp[2] += dj[5] * c.fy * (-g.jac[5] / c.fy * z) / z2;
  } else {
    dp[1] += -dj[5] * c.fy / z2;
    dp[2] += dj[5] * 2.0 * c.fy * y / z3;
  }
  // p = R mean + t
  double dmean[3];
  for (int j = 0; j < 3; ++j) dmean[j] = c.r[j] * dp[0] + c.r[3 + j] * dp[1] + c.r[6 + j] * dp[2];
  // Sigma = M M^T, M = Rq S
  double dm[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double acc = 0.0;
      for (int k = 0; k < 3; ++k) acc += (dsigma[3 * i + k] + dsigma[3 * k + i]) * g.rq[3 * k + j] * double(scale[j]);
      dm[3 * i + j] = acc;
    }
  double dr[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dr[3 * i + j] = dm[3 * i + j] * double(scale[j]);
  for (int j = 0; j < 3; ++j) {
    double acc = 0.0;
    for (int i = 0; i < 3; ++i) acc += dm[3 * i + j] * g.rq[3 * i + j];
    gs[j] += T(acc);
  }
  if (g.q_ok) {
    const double w = g.qn[0], qx = g.qn[1], qy = g.qn[2], qz = g.qn[3];
    const double dqn[4] = {
        2 * (-qz * dr[1] + qy * dr[2] + qz * dr[3] - qx * dr[5] - qy * dr[6] + qx * dr[7]),
        2 * (qy * dr[1] + qz * dr[2] + qy * dr[3] - 2 * qx * dr[4] - w * dr[5] + qz * dr[6] + w * dr[7] - 2 * qx * dr[8]),
        2 * (-2 * qy * dr[0] + qx * dr[1] + w * dr[2] + qx * dr[3] + qz * dr[5] - w * dr[6] + qz * dr[7] - 2 * qy * dr[8]),
        2 * (-2 * qz * dr[0] - w * dr[1] + qx * dr[2] + w * dr[3] - 2 * qz * dr[4] + qy * dr[5] + qx * dr[6] + qy * dr[7]),
    };
    const double dot = dqn[0] * w + dqn[1] * qx + dqn[2] * qy + dqn[3] * qz;
    for (int i = 0; i < 4; ++i) gq[i] += T((dqn[i] - g.qn[i] * dot) / g.qnorm);
  }
  if (sh_degree >= 0) sh_backward_entry<T>(c, mean, shc, K, sh_degree, g_rgb, gsh, dmean);
  for (int i = 0; i < 3; ++i) gm[i] += T(dmean[i]);
}

template <typename T>
void project_backward_impl(const torch::Tensor& means, const torch::Tensor& quats, const torch::Tensor& scales,
                           const torch::Tensor& sh, const torch::Tensor& viewmats, const torch::Tensor& ks,
                           int64_t width, int64_t height, int64_t sh_degree, const torch::Tensor& cam_ids,
                           const torch::Tensor& gauss_ids, const torch::Tensor& g_means2d,
                           const torch::Tensor& g_conics, const torch::Tensor& g_rgb, const torch::Tensor& g_depth,
                           bool geometry, torch::Tensor& gm, torch::Tensor& gq, torch::Tensor& gs, torch::Tensor& gsh) {
  const int64_t M = cam_ids.size(0), B = viewmats.size(0);
  const int64_t K = sh_degree >= 0 ? sh.size(1) : 0;
  const int64_t* cam = cam_ids.data_ptr<int64_t>();
  const int64_t* gid = gauss_ids.data_ptr<int64_t>();
  const T* mp = means.data_ptr<T>();
  const T* qp = quats.data_ptr<T>();
  const T* sp = scales.data_ptr<T>();
  const T* shp = sh_degree >= 0 ? sh.data_ptr<T>() : nullptr;
  T* shg = sh_degree >= 0 ? gsh.data_ptr<T>() : nullptr;
  const T* rgb_grad = sh_degree >= 0 ? g_rgb.data_ptr<T>() : nullptr;
  const T* gm2 = g_means2d.data_ptr<T>();
  const T* gcon = g_conics.data_ptr<T>();
  const T* gdep = g_depth.data_ptr<T>();
  int64_t start = 0;
  for (int64_t b = 0; b < B; ++b) {  // a Gaussian appears at most once per camera: no write races
    int64_t stop = start;
    while (stop < M && cam[stop] == b) ++stop;
    const Cam c = camera(viewmats.data_ptr<T>() + 16 * b, ks.data_ptr<T>() + 9 * b, width, height);
#pragma omp parallel for schedule(static) num_threads(std::max(1, at::get_num_threads()))
    for (int64_t e = start; e < stop; ++e) {
      const int64_t n = gid[e];
      if (!geometry) {
        if (shg)
          sh_backward_entry<T>(c, mp + 3 * n, shp + n * K * 3, K, int(sh_degree), rgb_grad + 3 * e, shg + n * K * 3,
                               nullptr);
        continue;
      }
      project_backward_entry<T>(c, mp + 3 * n, qp + 4 * n, sp + 3 * n, shp ? shp + n * K * 3 : nullptr, K,
                                int(sh_degree), gm2 + 2 * e, gcon + 3 * e, rgb_grad ? rgb_grad + 3 * e : nullptr,
                                double(gdep[e]), gm.data_ptr<T>() + 3 * n, gq.data_ptr<T>() + 4 * n,
                                gs.data_ptr<T>() + 3 * n, shg ? shg + n * K * 3 : nullptr);
    }
    start = stop;
  }
}

// The rows of the dense (B*N, ...) `dense` at `rows` (ascending), as a new (M, ...) tensor, in parallel.
torch::Tensor gather_rows(const torch::Tensor& dense, const std::vector<int64_t>& rows) {
  const int64_t m = int64_t(rows.size()), width = dense.numel() / std::max<int64_t>(1, dense.size(0) * dense.size(1));
  std::vector<int64_t> shape{m};
  for (int64_t d = 2; d < dense.dim(); ++d) shape.push_back(dense.size(d));
  auto out = torch::empty(shape, dense.options());
  if (m == 0 || width == 0) return out;
  const int64_t bytes = width * int64_t(dense.element_size());
  const char* src = static_cast<const char*>(dense.data_ptr());
  char* dst = static_cast<char*>(out.data_ptr());
#pragma omp parallel for schedule(static) num_threads(std::max(1, at::get_num_threads()))
  for (int64_t k = 0; k < m; ++k) std::memcpy(dst + k * bytes, src + rows[k] * bytes, size_t(bytes));
  return out;
}

}  // namespace

// Per (camera, Gaussian) projection, compacted to the visible entries (camera-major, then Gaussian index):
// means2d, conics, rgb (if sh_degree >= 0), depth, radii, tile rectangles, then cam_ids and gauss_ids (int64).
// The dense buffers are never zeroed: only the visible entries' rows are written and read.
std::vector<torch::Tensor> project_forward(torch::Tensor means, torch::Tensor quats, torch::Tensor scales,
                                           torch::Tensor opacities, torch::Tensor sh, torch::Tensor viewmats,
                                           torch::Tensor ks, int64_t width, int64_t height, double near, double far,
                                           int64_t sh_degree) {
  TORCH_CHECK(sh_degree <= 3, "SH degree must be at most 3");
  const int64_t B = viewmats.size(0), N = means.size(0);
  const auto opts = means.options();
  auto means2d = torch::empty({B, N, 2}, opts);
  auto conics = torch::empty({B, N, 3}, opts);
  auto rgb = torch::empty({B, N, sh_degree >= 0 ? 3 : 0}, opts);
  auto depth = torch::empty({B, N}, opts);
  auto radii = torch::empty({B, N, 2}, opts);
  auto rects = torch::empty({B, N, 4}, torch::dtype(torch::kInt32));
  auto valid = torch::empty({B, N}, torch::dtype(torch::kBool));
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "gt2gs_project", [&] {
    project_forward_impl<scalar_t>(means.contiguous(), quats.contiguous(), scales.contiguous(),
                                   opacities.contiguous(), sh.contiguous(), viewmats.contiguous(), ks.contiguous(),
                                   width, height, near, far, sh_degree, means2d, conics, rgb, depth, radii, rects,
                                   valid);
  });
  std::vector<int64_t> rows;
  rows.reserve(size_t(B * N));
  const bool* v = valid.data_ptr<bool>();
  for (int64_t e = 0; e < B * N; ++e)
    if (v[e]) rows.push_back(e);
  const int64_t m = int64_t(rows.size());
  auto cam_ids = torch::empty({m}, torch::dtype(torch::kInt64));
  auto gauss_ids = torch::empty({m}, torch::dtype(torch::kInt64));
  int64_t* ci = cam_ids.data_ptr<int64_t>();
  int64_t* gi = gauss_ids.data_ptr<int64_t>();
  for (int64_t k = 0; k < m; ++k) ci[k] = rows[k] / std::max<int64_t>(N, 1), gi[k] = rows[k] % std::max<int64_t>(N, 1);
  return {gather_rows(means2d, rows), gather_rows(conics, rows), gather_rows(rgb, rows), gather_rows(depth, rows),
          gather_rows(radii, rows), gather_rows(rects, rows), cam_ids, gauss_ids};
}

// Gradients of the entries (cam_ids, gauss_ids sorted by camera) w.r.t. means, quats, scales (when
// ``geometry``) and sh.
std::vector<torch::Tensor> project_backward(torch::Tensor means, torch::Tensor quats, torch::Tensor scales,
                                            torch::Tensor sh, torch::Tensor viewmats, torch::Tensor ks,
                                            int64_t width, int64_t height, int64_t sh_degree, torch::Tensor cam_ids,
                                            torch::Tensor gauss_ids, torch::Tensor g_means2d, torch::Tensor g_conics,
                                            torch::Tensor g_rgb, torch::Tensor g_depth, bool geometry) {
  means = means.contiguous();
  quats = quats.contiguous();
  scales = scales.contiguous();
  sh = sh.contiguous();
  viewmats = viewmats.contiguous();
  ks = ks.contiguous();
  cam_ids = cam_ids.contiguous();
  gauss_ids = gauss_ids.contiguous();
  g_means2d = g_means2d.contiguous();
  g_conics = g_conics.contiguous();
  g_rgb = g_rgb.contiguous();
  g_depth = g_depth.contiguous();
  // without ``geometry`` only the SH gradient is computed (the geometry's are empty): a colour-only step
  auto geometry_grad = [&](const torch::Tensor& t) { return geometry ? torch::zeros_like(t) : t.new_empty({0}); };
  auto gm = geometry_grad(means), gq = geometry_grad(quats), gs = geometry_grad(scales);
  auto gsh = torch::zeros_like(sh);
  AT_DISPATCH_FLOATING_TYPES(means.scalar_type(), "gt2gs_project_backward", [&] {
    project_backward_impl<scalar_t>(means, quats, scales, sh, viewmats, ks, width, height, sh_degree, cam_ids,
                                    gauss_ids, g_means2d, g_conics, g_rgb, g_depth, geometry, gm, gq, gs, gsh);
  });
  return {gm, gq, gs, gsh};
}
