#!/usr/bin/env python3
"""Independent reference for the gamma candidate of `model/src/life/fits.rs` on a flat ridge: the
maximum of the censored gamma likelihood of the manual's wear job at 887 operations (3 failures at
874, 881 and 886 operations of 300 devices, 297 censored at 887), where the likelihood is so flat
along the shape that a search on its values alone stops 1e-6 off (the test
`the_gamma_on_a_flat_ridge_is_at_its_maximum`).

    pip install mpmath
    python3 tools/gamma_ridge_reference.py

mpmath at 40 digits: the log-likelihood (log density of each failure, log survival, the
regularised upper incomplete gamma, of each censored device) maximised by Newton's method on its
score in (ln shape, ln scale), derivatives by mpmath's own differentiation. Shares no code with the
Rust module.
"""
import mpmath as mp

mp.mp.dps = 40
FAILURES = [874, 881, 886]
CENSORED = [(887, 297)]


def log_likelihood(u, v):
    shape, scale = mp.e ** u, mp.e ** v
    ll = mp.mpf(0)
    for t in FAILURES:
        ll += (shape - 1) * mp.log(t) - t / scale - shape * v - mp.loggamma(shape)
    for t, count in CENSORED:
        ll += count * mp.log(mp.gammainc(shape, t / scale, mp.inf, regularized=True))
    return ll


def maximum(u, v):
    for _ in range(60):
        g = [mp.diff(lambda x: log_likelihood(x, v), u), mp.diff(lambda y: log_likelihood(u, y), v)]
        h00 = mp.diff(lambda x: log_likelihood(x, v), u, 2)
        h11 = mp.diff(lambda y: log_likelihood(u, y), v, 2)
        h01 = mp.diff(lambda x: mp.diff(lambda y: log_likelihood(x, y), v), u)
        det = h00 * h11 - h01 * h01
        du = -(h11 * g[0] - h01 * g[1]) / det
        dv = -(h00 * g[1] - h01 * g[0]) / det
        u, v = u + du, v + dv
        if abs(du) + abs(dv) < mp.mpf(10) ** -30:
            break
    return u, v


if __name__ == "__main__":
    u, v = maximum(mp.log(2212.37), mp.log(0.42148))
    print(f"shape {mp.nstr(mp.e ** u, 20)} scale {mp.nstr(mp.e ** v, 20)} "
          f"log-likelihood {mp.nstr(log_likelihood(u, v), 20)}")
