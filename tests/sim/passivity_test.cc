// The port's passivity observer and controller (sim/src/passivity.cc) and the sampled-data device
// model (port_model.cc): the observer against closed forms, a stiff wall that is active without the
// controller and passive with it, zero and non-finite input, the damping cap, no allocation.
#include "idms/sim/passivity.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "alloc_counter.h"
#include "idms/sim/port_model.h"

namespace idms {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

PassivityOptions Options(bool enabled, double dt_s = 1e-3) {
  PassivityOptions o;
  o.enabled = enabled;
  o.dt_s = dt_s;
  o.window_s = 0.1;
  o.max_damping = 0.5;
  o.quantum = 1e-4;
  return o;
}

// A zero-order-held spring F(k) = -K x(k) under a prescribed motion: the observer's sum telescopes,
// E(n) = K/2 (x(n)^2 - x(0)^2) - K/2 sum (x(k) - x(k-1))^2; over whole periods only the second
// term is left: the sampled spring hands the hand K/2 sum dx^2 (what makes a stiff wall buzz).
TEST(Passivity, ObserverMatchesTheZeroOrderHeldSpringInClosedForm) {
  const double k = 300, amplitude = 0.2, dt = 1e-3, omega = 2 * M_PI * 7;
  PassivityController pc(Options(false));
  double sum_dx2 = 0, x_prev = 0, x0 = 0;
  for (int n = 0; n <= 2000; ++n) {
    const double x = amplitude * std::sin(omega * n * dt + 0.3);
    if (n == 0) x0 = x;
    if (n > 0) sum_dx2 += (x - x_prev) * (x - x_prev);
    x_prev = x;
    const double pos[3] = {0, 0, x};
    const double f[3] = {0, 0, -k * x};
    double out[3];
    const PassivityTick t = pc.Update(pos, true, f, 0, out);
    pc.Commanded(out);
    EXPECT_EQ(out[2], f[2]);  // the controller is off
    const double expected = k / 2 * (x * x - x0 * x0) - k / 2 * sum_dx2;
    ASSERT_NEAR(t.energy, expected, 1e-12 * k * amplitude * amplitude) << "tick " << n;
  }
  EXPECT_NEAR(pc.energy(), -k / 2 * sum_dx2 + k / 2 * (x_prev * x_prev - x0 * x0), 1e-12);
}

// A constant force pushed through a displacement: E = -F . (x(n) - x(0)), in any direction.
TEST(Passivity, ObserverCountsAConstantForcesWork) {
  PassivityController pc(Options(false));
  const double f[3] = {0.5, -1, 2};
  double out[3];
  for (int n = 0; n <= 100; ++n) {
    const double pos[3] = {0.01 * n, 0.02 * n, -0.005 * n};
    pc.Update(pos, true, f, 0, out);
    pc.Commanded(out);
  }
  EXPECT_NEAR(pc.energy(), -(0.5 * 1 - 1 * 2 + 2 * -0.5), 1e-12);
  EXPECT_NEAR(pc.work_in(), 2.0 - 0.5 + 1.0, 1e-12);  // every increment was positive
}

struct WallRun {
  double min_energy = 0, min_window = 0;
  double late_swing = 0;  // peak-to-peak of z over the last half second
  double max_force = 0;
  double dissipated = 0;
  uint64_t acted = 0;
  bool finite = true;
};

// The hand presses 0.05 into a wall at z = 0 of stiffness k: F = -k z (z > 0), at period dt, the
// force clamped at 10 like the device's guard.
WallRun PressAWall(double k, double dt, bool controller) {
  PortModelOptions device;
  device.dof = 1;
  device.dt_s = dt;
  const double start[3] = {0, 0, -0.02};
  PortModel port(device, start);
  PassivityOptions po = Options(controller, dt);
  po.max_damping = 1.5;  // below the device's m / T = 3.5, where a sampled damper turns active
  PassivityController pc(po);
  WallRun run;
  const int ticks = static_cast<int>(std::lround(3.0 / dt));
  double z_min = 1e9, z_max = -1e9;
  double force[3] = {0, 0, 0};
  for (int n = 0; n < ticks; ++n) {
    double pos[3];
    port.Read(pos);
    const double f_env[3] = {0, 0, pos[2] > 0 ? -k * pos[2] : 0};
    pc.Update(pos, true, f_env, 0, force);
    const double norm = std::abs(force[2]);
    if (norm > 10) force[2] *= 10 / norm;
    pc.Commanded(force);
    run.max_force = std::max(run.max_force, std::abs(force[2]));
    const double target[3] = {0, 0, 0.05};
    port.Advance(force, target);
    run.finite = run.finite && std::isfinite(port.pos()[2]);
    if (n * dt > 2.5) z_min = std::min(z_min, port.pos()[2]), z_max = std::max(z_max, port.pos()[2]);
  }
  run.min_energy = pc.min_energy();
  run.min_window = pc.min_window_energy();
  run.late_swing = z_max - z_min;
  run.dissipated = pc.dissipated();
  run.acted = pc.acted_ticks();
  return run;
}

// Colgate's bound for this device and grip: K < 2 (b + c) / T = 2 * 0.07 / 2 ms = 70. A wall of 700
// at 500 Hz buzzes against its clamp without the controller, and holds with it.
TEST(Passivity, AStiffWallAtALowRateIsActiveWithoutTheControllerAndPassiveWithIt) {
  const double dt = 2e-3, k = 700;
  const WallRun off = PressAWall(k, dt, false);
  const WallRun on = PressAWall(k, dt, true);
  // Without: a limit cycle at the clamp, and energy handed to the hand.
  EXPECT_GT(off.late_swing, 0.01) << "the uncontrolled wall did not buzz: the test could not fail";
  EXPECT_LT(off.min_energy, -0.01);
  EXPECT_EQ(off.acted, 0u);
  // With: held still (the hand's static press is 0.05 * 10 / (10 + 700) deep), never below -eps.
  // eps: one tick's misprediction, F_max (F_max T^2 / m + 2 q) with m = device + hand mass, paid back
  // the tick after.
  const double eps = 10 * (10 * dt * dt / 0.007 + 2e-4);
  EXPECT_TRUE(on.finite);
  EXPECT_LT(on.late_swing, 5e-4);
  EXPECT_GE(on.min_window, -eps);
  EXPECT_GE(on.min_energy, -eps);
  EXPECT_GT(on.acted, 0u);
  EXPECT_GT(on.dissipated, 0);
}

// Below Colgate's bound the wall is passive on its own: the controller barely acts.
TEST(Passivity, ASoftWallNeedsLittleOfTheController) {
  const WallRun on = PressAWall(30, 1e-3, true);
  EXPECT_LT(on.late_swing, 5e-4);
  EXPECT_GE(on.min_energy, -1e-3);
}

TEST(Passivity, ZeroVelocityAndNonFiniteInputGiveFiniteForces) {
  PassivityController pc(Options(true));
  double out[3];
  // An energy debt first: the tool moves with the force (the environment pushes it along).
  const double f[3] = {0, 0, 5};
  for (int n = 0; n < 5; ++n) {
    const double pos[3] = {0, 0, 0.01 * n};
    pc.Update(pos, true, f, 0, out);
    pc.Commanded(f);  // as if the device ignored the damping: the debt stays
  }
  ASSERT_LT(pc.window_energy(), 0);
  // Still: no velocity, no damping, the force as asked.
  const double still[3] = {0, 0, 0.04};
  PassivityTick t = pc.Update(still, true, f, 0, out);
  EXPECT_EQ(t.damping, 0);
  EXPECT_FALSE(t.acted);
  EXPECT_EQ(out[2], 5);
  pc.Commanded(out);
  // A NaN position: no observation, nothing added, the sums unchanged.
  const double e = pc.energy();
  const double nan_pos[3] = {kNaN, 0, 0};
  t = pc.Update(nan_pos, true, f, 0, out);
  EXPECT_EQ(t.damping, 0);
  EXPECT_EQ(pc.energy(), e);
  EXPECT_TRUE(std::isfinite(out[0]) && std::isfinite(out[1]) && std::isfinite(out[2]));
  pc.Commanded(out);
  // A NaN or infinite force: sent as zero; a NaN commanded force is not remembered.
  const double bad_f[3] = {kNaN, std::numeric_limits<double>::infinity(), 1};
  const double moved[3] = {0, 0, 0.05};
  t = pc.Update(moved, true, bad_f, kNaN, out);
  EXPECT_EQ(out[0], 0);
  EXPECT_EQ(out[1], 0);
  EXPECT_TRUE(std::isfinite(out[2]));
  pc.Commanded(bad_f);
  const double later[3] = {0, 0, 0.06};
  t = pc.Update(later, true, f, 0, out);
  EXPECT_TRUE(std::isfinite(pc.energy()) && std::isfinite(pc.window_energy()) && std::isfinite(t.damping));
  EXPECT_TRUE(std::isfinite(out[2]));
}

TEST(Passivity, DampingIsCappedAtTheDevicesLimit) {
  PassivityOptions o = Options(true);
  o.max_damping = 0.25;
  PassivityController pc(o);
  double out[3];
  const double f[3] = {0, 0, 8};
  for (int n = 0; n < 3; ++n) {
    const double pos[3] = {0, 0, 0.02 * n};  // 20 units/s with a force of 8 along it: a large debt
    const PassivityTick t = pc.Update(pos, true, f, 0, out);
    if (n >= 1) {
      EXPECT_EQ(t.damping, 0.25);
      EXPECT_NEAR(out[2], 8 - 0.25 * 20, 1e-9);
    }
    pc.Commanded(out);
  }
}

// Credit the environment no longer stores is forgotten after the window: a session's dissipated
// total does not let a later burst of generated energy through.
TEST(Passivity, TheWindowForgetsDissipatedCreditButNotStoredEnergy) {
  PassivityController pc(Options(true));
  double out[3];
  // 0.5 s of pushing against a damper: every tick deposits.
  double z = 0;
  for (int n = 0; n < 500; ++n, z += 1e-3) {
    const double pos[3] = {0, 0, z};
    const double f[3] = {0, 0, -2};
    pc.Update(pos, true, f, 0, out);
    pc.Commanded(out);
  }
  EXPECT_NEAR(pc.energy(), 2 * 0.499, 1e-9);
  EXPECT_LT(pc.window_energy(), 0.25);  // about the last 0.1 s
  // Standing still for longer than the window: the credit is gone unless stored.
  for (int n = 0; n < 200; ++n) {
    const double pos[3] = {0, 0, z - 1e-3};
    const double f[3] = {0, 0, 0};
    pc.Update(pos, true, f, n < 100 ? 0.0 : 0.3, out);
    pc.Commanded(out);
  }
  EXPECT_NEAR(pc.window_energy(), 0, 1e-12);  // capped at 0 by the ticks that stored nothing
  EXPECT_NEAR(pc.energy(), 0.998, 1e-9);
}

TEST(Passivity, AStoredEnergyKeepsItsCredit) {
  PassivityController pc(Options(true));
  double out[3];
  double z = 0;
  for (int n = 0; n < 500; ++n, z += 1e-3) {
    const double pos[3] = {0, 0, z};
    const double f[3] = {0, 0, -2};
    pc.Update(pos, true, f, 1.0, out);  // a spring that holds what was put in
    pc.Commanded(out);
  }
  EXPECT_NEAR(pc.window_energy(), 0.998, 1e-9);
}

TEST(Passivity, UpdateAllocatesNothing) {
  PassivityController pc(Options(true));
  double out[3];
  const int64_t before = test::AllocationCount();
  for (int n = 0; n < 1000; ++n) {
    const double pos[3] = {0, 0, 1e-3 * (n % 7)};
    const double f[3] = {0, 0, 3};
    pc.Update(pos, true, f, 0.1, out);
    pc.Commanded(out);
  }
  EXPECT_EQ(test::AllocationCount(), before);
}

}  // namespace
}  // namespace idms
