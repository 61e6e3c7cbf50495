/*
 * Scalar C loops of gonio's closed-form BRDFs: the reference implementation class that
 * peer renderers ship (one double-precision evaluation per geometry, compiled -O2).
 * benchmarks/closed_form_speed.py compiles this file, checks every function against
 * gonio's numpy path for equality (relative 1e-12) and times both on the same inputs.
 *
 * All angles in radians; arrays of length n; output BRDF [1/sr].
 * Formulas: Forsyth & Ponce ch. 2 (Lambert, Phong), Minnaert as quoted by Oren & Nayar
 * section 1, Oren & Nayar (1995) eq 33-35 (functional approximation) and eq 36
 * (qualitative model).
 */
#include <math.h>
#include <stddef.h>

void lambert(size_t n, const double *ti, const double *pi_, const double *tr,
             const double *pr, double rho, double *out) {
    (void)ti; (void)pi_; (void)tr; (void)pr;
    for (size_t k = 0; k < n; ++k) out[k] = rho / M_PI;
}

void minnaert(size_t n, const double *ti, const double *pi_, const double *tr,
              const double *pr, double rho, double kexp, double *out) {
    (void)pi_; (void)pr;
    for (size_t k = 0; k < n; ++k) {
        double c = cos(ti[k]) * cos(tr[k]);
        if (c < 0.0) c = 0.0;
        out[k] = rho * (kexp + 1.0) / (2.0 * M_PI) * pow(c, kexp - 1.0);
    }
}

void phong(size_t n, const double *ti, const double *pi_, const double *tr,
           const double *pr, double rho_s, double e, double *out) {
    for (size_t k = 0; k < n; ++k) {
        double c = cos(ti[k]) * cos(tr[k]) - sin(ti[k]) * sin(tr[k]) * cos(pr[k] - pi_[k]);
        if (c < 0.0) c = 0.0;
        out[k] = rho_s * (e + 2.0) / (2.0 * M_PI) * pow(c, e);
    }
}

void lambert_phong(size_t n, const double *ti, const double *pi_, const double *tr,
                   const double *pr, double rho, double rho_s, double e, double *out) {
    for (size_t k = 0; k < n; ++k) {
        double c = cos(ti[k]) * cos(tr[k]) - sin(ti[k]) * sin(tr[k]) * cos(pr[k] - pi_[k]);
        if (c < 0.0) c = 0.0;
        out[k] = rho / M_PI + rho_s * (e + 2.0) / (2.0 * M_PI) * pow(c, e);
    }
}

/* Oren & Nayar eq 33-35 divided by E0 cos(theta_i); sigma in radians. */
void oren_nayar(size_t n, const double *ti, const double *pi_, const double *tr,
                const double *pr, double rho, double sigma, double ir_weight, double *out) {
    double s2 = sigma * sigma;
    double c1 = 1.0 - 0.5 * s2 / (s2 + 0.33);
    double c2_scale = 0.45 * s2 / (s2 + 0.09);
    double c3_scale = 0.125 * s2 / (s2 + 0.09);
    double ir_scale = ir_weight * 0.17 * rho * s2 / (s2 + 0.13);
    for (size_t k = 0; k < n; ++k) {
        double alpha = ti[k] > tr[k] ? ti[k] : tr[k];
        double beta = ti[k] > tr[k] ? tr[k] : ti[k];
        double cphi = cos(pr[k] - pi_[k]);
        double c2 = cphi >= 0.0 ? c2_scale * sin(alpha)
                                : c2_scale * (sin(alpha) - pow(2.0 * beta / M_PI, 3.0));
        double r = 4.0 * alpha * beta / (M_PI * M_PI);
        double c3 = c3_scale * r * r;
        double direct = c1 + cphi * c2 * tan(beta)
                        + (1.0 - fabs(cphi)) * c3 * tan(0.5 * (alpha + beta));
        double b = 2.0 * beta / M_PI;
        double inter = ir_scale * (1.0 - cphi * b * b);
        out[k] = rho / M_PI * (direct + inter);
    }
}

/* Oren & Nayar eq 36 (qualitative model) divided by E0 cos(theta_i). */
void oren_nayar_qualitative(size_t n, const double *ti, const double *pi_, const double *tr,
                            const double *pr, double rho, double sigma, double a_constant,
                            double *out) {
    double s2 = sigma * sigma;
    double a = 1.0 - 0.5 * s2 / (s2 + a_constant);
    double bcoef = 0.45 * s2 / (s2 + 0.09);
    for (size_t k = 0; k < n; ++k) {
        double alpha = ti[k] > tr[k] ? ti[k] : tr[k];
        double beta = ti[k] > tr[k] ? tr[k] : ti[k];
        double cphi = cos(pr[k] - pi_[k]);
        if (cphi < 0.0) cphi = 0.0;
        out[k] = rho / M_PI * (a + bcoef * cphi * sin(alpha) * tan(beta));
    }
}

/* Unpolarised Fresnel reflectance from the cosines of the incidence and transmission
   angles, relative index m (Wolff, Nayar & Oren 1998, eq 2, amplitude form). */
static double fresnel_from_cosines(double cos_i, double cos_t, double m) {
    double rs = (cos_i - m * cos_t) / (cos_i + m * cos_t);
    double rp = (m * cos_i - cos_t) / (m * cos_i + cos_t);
    return 0.5 * (rs * rs + rp * rp);
}

/* Wolff, Nayar & Oren (1998) eq 7 with the free-albedo scale rho/pi and the exact
   Fresnel factors: entering at theta_i (index n), leaving towards theta_r (index 1/n). */
void wolff(size_t n, const double *ti, const double *pi_, const double *tr,
           const double *pr, double rho, double index, double *out) {
    (void)pi_; (void)pr;
    double inv_sq = 1.0 / (index * index);
    for (size_t k = 0; k < n; ++k) {
        double ci = cos(ti[k]), cr = cos(tr[k]);
        double ct = sqrt(1.0 - (1.0 - ci * ci) * inv_sq);   /* refracted, entering */
        double cin = sqrt(1.0 - (1.0 - cr * cr) * inv_sq);  /* internal, leaving */
        double entry = 1.0 - fresnel_from_cosines(ci, ct, index);
        double leave = 1.0 - fresnel_from_cosines(cin, cr, 1.0 / index);
        out[k] = rho / M_PI * entry * leave;
    }
}

/* Koenderink & van Doorn (1998) eq 26-28: the isotropic series of radial order 2 with
   amplitudes a[0..4] of I_000, I_111, I_200, I_220, I_222; R_1^1 = rho, R_2^0 = 1 - 2 cos,
   R_2^2 = rho^2 with rho^2 = 1 - cos(theta) (eq 10). */
void kvd2(size_t n, const double *ti, const double *pi_, const double *tr,
          const double *pr, double a000, double a111, double a200, double a220,
          double a222, double *out) {
    const double s = 1.0 / (2.0 * M_PI);
    const double k000 = 0.5 * s * 2.0, k111 = sqrt(2.0) * s * 2.0, k200 = sqrt(1.5) * s;
    const double k220 = 1.5 * s * 2.0, k222 = sqrt(4.5) * s * 2.0;
    for (size_t k = 0; k < n; ++k) {
        double ci = cos(ti[k]), cr = cos(tr[k]), cd = cos(pr[k] - pi_[k]);
        double qi = 1.0 - ci, qr = 1.0 - cr;               /* rho^2 */
        double zi = 1.0 - 2.0 * ci, zr = 1.0 - 2.0 * cr;   /* R_2^0 */
        out[k] = a000 * k000 + a111 * k111 * sqrt(qi * qr) * cd + a200 * k200 * (zi + zr)
                 + a220 * k220 * zi * zr + a222 * k222 * qi * qr * (2.0 * cd * cd - 1.0);
    }
}
