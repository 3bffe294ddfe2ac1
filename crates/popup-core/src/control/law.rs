//! The discrete-time control laws, exactly as they run at the controller period `T` [s].
//! Tick `k` happens at `t_k = t_0 + k T`; inputs are sampled at `t_k` and the output is
//! held until `t_{k+1}` (zero-order hold). See `docs/control.md` for the equations.

/// First-order low-pass `y_k = y_{k-1} + β (x_k − y_{k-1})`, `β = 1 − exp(−ω_f T)`: the
/// exact zero-order-hold discretisation of `ẏ = ω_f (x − y)` [ω_f in rad/s].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lpf {
    /// β [-] (1 = no filtering).
    pub beta: f64,
}

impl Lpf {
    /// Filter with corner `omega` [rad/s] at period `period` [s] (`omega = ∞` passes through).
    pub fn new(omega: f64, period: f64) -> Lpf {
        Lpf { beta: if omega.is_finite() { 1.0 - (-omega * period).exp() } else { 1.0 } }
    }

    /// One tick: returns the new output.
    #[inline]
    pub fn step(&self, y: &mut f64, x: f64) -> f64 {
        *y += self.beta * (x - *y);
        *y
    }
}

/// PI with conditional-integration anti-windup:
///
/// `u_k = Kp e_k + I_k`, output `ū_k = clamp(u_k, −u_max, u_max)`;
/// `I_{k+1} = I_k + Ki T e_k` unless the output is saturated and `e_k` pushes further
/// into saturation (then `I_{k+1} = I_k`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pi {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain [per second times the proportional unit].
    pub ki: f64,
    /// Output limit (symmetric; `∞` = none).
    pub u_max: f64,
}

impl Pi {
    /// One tick with error `e` and integrator state `i` at period `period` [s]. Returns the
    /// clamped output and whether it saturated.
    #[inline]
    pub fn step(&self, i: &mut f64, e: f64, period: f64) -> (f64, bool) {
        let u = self.kp * e + *i;
        let us = u.clamp(-self.u_max, self.u_max);
        let sat = us != u;
        if !sat || (u > 0.0) != (e > 0.0) {
            *i += self.ki * period * e;
        }
        (us, sat)
    }
}

/// PID on an already filtered signal `y` (desired value 0):
/// `u_k = Kp y_k + Ki S_k + Kd (y_k − y_{k−1}) / T`, `S_{k+1} = S_k + T y_k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pid {
    /// Proportional gain.
    pub kp: f64,
    /// Integral gain.
    pub ki: f64,
    /// Derivative gain.
    pub kd: f64,
}

/// State of a [`Pid`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PidState {
    /// Running integral S_k.
    pub s: f64,
    /// Previous input y_{k−1}.
    pub y_prev: f64,
}

impl Pid {
    /// One tick with input `y` at period `period` [s].
    #[inline]
    pub fn step(&self, st: &mut PidState, y: f64, period: f64) -> f64 {
        let u = self.kp * y + self.ki * st.s + self.kd * (y - st.y_prev) / period;
        st.s += period * y;
        st.y_prev = y;
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lpf_matches_continuous_step_response() {
        let (w, t) = (13.5, 1e-3);
        let f = Lpf::new(w, t);
        let mut y = 0.0;
        for k in 1..=500 {
            f.step(&mut y, 1.0);
            let exact = 1.0 - (-w * t * k as f64).exp();
            assert!((y - exact).abs() < 1e-12, "k={k}: {y} vs {exact}");
        }
    }

    #[test]
    fn pi_integrates_and_stops_when_saturated() {
        let pi = Pi { kp: 2.0, ki: 10.0, u_max: 1.0 };
        let mut i = 0.0;
        let (u, sat) = pi.step(&mut i, 0.1, 0.01);
        assert_eq!((u, sat), (0.2, false));
        assert!((i - 0.01).abs() < 1e-15);
        // saturated and pushing further: integrator frozen
        let (u, sat) = pi.step(&mut i, 5.0, 0.01);
        assert_eq!((u, sat), (1.0, true));
        assert!((i - 0.01).abs() < 1e-15);
        // saturated high but the error reversing: integrates (unwinds)
        let mut i = 2.0;
        let (u, sat) = pi.step(&mut i, -0.1, 0.01);
        assert_eq!((u, sat), (1.0, true));
        assert!((i - (2.0 - 0.01)).abs() < 1e-15);
    }

    #[test]
    fn pid_terms() {
        let pid = Pid { kp: 1.0, ki: 2.0, kd: 0.5 };
        let mut st = PidState::default();
        let u0 = pid.step(&mut st, 1.0, 0.1);
        assert!((u0 - (1.0 + 0.0 + 0.5 * 10.0)).abs() < 1e-12);
        let u1 = pid.step(&mut st, 1.0, 0.1);
        assert!((u1 - (1.0 + 2.0 * 0.1)).abs() < 1e-12);
    }
}
