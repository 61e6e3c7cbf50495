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
