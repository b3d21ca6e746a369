"""A motor-level quadrotor (ArduPilot frame class 1, type 1: quad X) for ArduPilot SITL's JSON physics.

Rigid-body 6-DOF motion in NED (earth) and FRD (body) frames, driven by four motors whose PWM goes
through ArduPilot's thrust curve, a first-order motor lag, per-motor yaw torque, quadratic body drag,
per-motor momentum drag, rotational damping, gravity and a ground the vehicle rests on. The drag and the
rotors see the velocity through the air (the vehicle's minus the wind's, as `SIM_Frame::calculate_forces`).

Every magnitude comes from ArduPilot's own SITL multicopter model, so that ArduCopter's default gains
(tuned on that model) fly it:

- `libraries/SITL/SIM_Frame.h` (`Frame::Model` defaults) and `SIM_Frame.cpp` (`Frame::init`,
  `Frame::calculate_forces`): mass, diagonal size, hover throttle, thrust expo, spin and PWM range, slew
  rate, disc area, momentum-drag coefficient, reference drag test, reference rotation rate, battery;
- `libraries/SITL/SIM_Motor.cpp`: PWM to command, thrust from outflow and inflow velocity, yaw torque,
  momentum drag, motor position from the motor's angle;
- `libraries/SITL/SIM_Frame.cpp` (`quad_x_motors`) and `libraries/AP_Motors/AP_MotorsMatrix.cpp`
  (quad X): motor numbering, angles and spin directions;
- `Tools/autotest/default_params/copter.parm`: MOT_THST_EXPO 0.65, MOT_THST_HOVER 0.39.

The thesis (seed 000) names a quadcopter but gives no mass, size or motor data, so none is taken from it.
Deterministic: no randomness and no wall clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

GRAVITY_M_S2 = 9.80665  # AP_Math/definitions.h GRAVITY_MSS

# Quad X as SIM_Frame.cpp `quad_x_motors` and AP_MotorsMatrix.cpp (FRAME_CLASS 1, FRAME_TYPE 1):
# (motor angle from the nose in degrees, clockwise seen from above; yaw factor: CCW +1, CW -1,
# AP_MotorsMatrix.h AP_MOTORS_MATRIX_YAW_FACTOR_CCW/CW). Index i is motor i+1 on servo output i+1.
QUAD_X_MOTORS_DEG_YAW: tuple[tuple[float, float], ...] = (
    (45.0, 1.0),     # motor 1: front right, CCW
    (-135.0, 1.0),   # motor 2: back left, CCW
    (-45.0, -1.0),   # motor 3: front left, CW
    (135.0, -1.0),   # motor 4: back right, CW
)


def isa_air_density_kg_m3(altitude_amsl_m: float) -> float:
    """ISA troposphere air density at `altitude_amsl_m` (as AP_Baro::get_air_density_for_alt_amsl)."""
    temperature_k = 288.15 - 0.0065 * altitude_amsl_m
    pressure_pa = 101325.0 * (temperature_k / 288.15) ** 5.25588
    return pressure_pa / (287.26 * temperature_k)


@dataclass(frozen=True, kw_only=True)
class QuadXFrame:
    """The airframe's parameters; defaults are SIM_Frame.h's `Frame::Model` (the `--model quad` frame).

    Units are in the names. The motors' distance from the centre is `diagonal_size_m`, as
    SIM_Motor::setup_params places them (position = (cos, sin)(angle) * diagonal_size).
    """

    mass_kg: float = 3.0                      # SIM_Frame.h Model.mass
    diagonal_size_m: float = 0.35             # SIM_Frame.h Model.diagonal_size
    hover_throttle: float = 0.39              # SIM_Frame.h Model.hoverThrOut; copter.parm MOT_THST_HOVER
    thrust_expo: float = 0.65                 # SIM_Frame.h Model.propExpo; copter.parm MOT_THST_EXPO
    spin_min: float = 0.15                    # SIM_Frame.h Model.spin_min; MOT_SPIN_MIN default
    spin_max: float = 0.95                    # SIM_Frame.h Model.spin_max; MOT_SPIN_MAX default
    pwm_min_us: float = 1000.0                # SIM_Frame.h Model.pwmMin; MOT_PWM_MIN / RC3_MIN (copter.parm)
    pwm_max_us: float = 2000.0                # SIM_Frame.h Model.pwmMax; MOT_PWM_MAX / RC3_MAX (copter.parm)
    motor_slew_max_per_s: float = 150.0       # SIM_Frame.h Model.slew_max (command units per s; 0: none)
    # First-order motor lag before the slew limit. Fitted, not measured: SIM_Motor has no lag (slew limit
    # only) and the thesis gives no motor data. 3 ms is the lag with which ArduCopter 4.6.3's default rate
    # gains hold this frame in a clean hover (benchmarks/json_bridge_hover.py: mean motor spread 0.001);
    # at 5 ms the motors oscillate (spread 0.22), at 1/150 s (slew_max as a time constant) 0.58.
    motor_time_constant_s: float = 0.003
    disc_area_m2: float = 0.385               # SIM_Frame.h Model.disc_area (4 x 0.35 m rotors)
    momentum_drag_coef: float = 0.2           # SIM_Frame.h Model.mdrag_coef
    ref_speed_m_s: float = 15.08              # SIM_Frame.h Model.refSpd (drag test at fixed angle)
    ref_angle_deg: float = 45.0               # SIM_Frame.h Model.refAngle
    ref_voltage_v: float = 12.09              # SIM_Frame.h Model.refVoltage (hover power)
    ref_current_a: float = 29.3               # SIM_Frame.h Model.refCurrent (hover power)
    ref_altitude_amsl_m: float = 593.0        # SIM_Frame.h Model.refAlt
    ref_rotation_rate_deg_s: float = 120.0    # SIM_Frame.h Model.refRotRate (rotational damping)
    battery_max_voltage_v: float = 4.2 * 3    # SIM_Frame.h Model.maxVoltage (3S full)
    battery_voltage_v: float = 4.2 * 3        # constant battery: a full 3S pack, as SIM_BATT_VOLTAGE's default
    # Moments of inertia about body x, y, z; None: SIM_Frame::init's estimate (half the mass on a ring).
    inertia_frd_kg_m2: tuple[float, float, float] | None = None
    motors_deg_yaw: tuple[tuple[float, float], ...] = field(default=QUAD_X_MOTORS_DEG_YAW)

    def __post_init__(self) -> None:
        if self.mass_kg <= 0 or self.diagonal_size_m <= 0:
            raise ValueError("mass_kg and diagonal_size_m must be positive")
        if not 0.0 < self.hover_throttle < 1.0 or not 0.0 <= self.thrust_expo <= 1.0:
            raise ValueError("hover_throttle must be in (0, 1) and thrust_expo in [0, 1]")
        if not 0.0 <= self.spin_min < self.spin_max <= 1.0 or self.pwm_min_us >= self.pwm_max_us:
            raise ValueError("need 0 <= spin_min < spin_max <= 1 and pwm_min_us < pwm_max_us")
        if self.motor_time_constant_s < 0:
            raise ValueError("motor_time_constant_s must not be negative")

    # --- derived magnitudes, as SIM_Frame::init computes them -------------------------------------

    @property
    def inertia_kg_m2(self) -> tuple[float, float, float]:
        """Moments of inertia about body x, y, z (kg m^2); SIM_Frame::init's estimate unless given."""
        if self.inertia_frd_kg_m2 is not None:
            return self.inertia_frd_kg_m2
        ring = (self.diagonal_size_m * 0.5) ** 2
        ixx = self.mass_kg * 0.25 * ring
        return (ixx, ixx, self.mass_kg * 0.5 * ring)

    @property
    def air_density_kg_m3(self) -> float:
        """Air density at the reference altitude (constant: the model ignores its own height)."""
        return isa_air_density_kg_m3(self.ref_altitude_amsl_m)

    @property
    def max_thrust_per_motor_n(self) -> float:
        """One motor's thrust at command 1 and full battery (N).

        SIM_Motor::calc_thrust gives thrust = 0.5 rho A_eff v_max^2 * ((1-expo) c + expo c^2) with
        v_max = v_hover / sqrt(hoverThrOut): the four motors lift the weight where ArduPilot's
        linearised throttle is hoverThrOut.
        """
        return self.mass_kg * GRAVITY_M_S2 / len(self.motors_deg_yaw) / self.hover_throttle

    @property
    def max_outflow_velocity_m_s(self) -> float:
        """SIM_Frame::init's velocity_max: 2 * hover power / hover thrust / sqrt(hoverThrOut) (m/s)."""
        hover_velocity_out = 2.0 * self.ref_voltage_v * self.ref_current_a / (self.mass_kg * GRAVITY_M_S2)
        return hover_velocity_out / math.sqrt(self.hover_throttle)

    def _drag_terms(self) -> tuple[float, float]:
        """(areaCd in m^2, momentum-drag coefficient) from SIM_Frame::init's reference drag test."""
        rho = self.air_density_kg_m3
        drag_force = self.mass_kg * GRAVITY_M_S2 * math.tan(math.radians(self.ref_angle_deg))
        cos_tilt = math.cos(math.radians(self.ref_angle_deg))
        airspeed_bf = self.ref_speed_m_s * cos_tilt
        ref_thrust = self.mass_kg * GRAVITY_M_S2 / cos_tilt
        mdrag = self.momentum_drag_coef
        momentum_drag = cos_tilt * mdrag * airspeed_bf * math.sqrt(ref_thrust * rho * self.disc_area_m2)
        if momentum_drag > drag_force:
            return 0.0, mdrag * drag_force / momentum_drag
        return (drag_force - momentum_drag) / (0.5 * rho * self.ref_speed_m_s ** 2), mdrag

    @property
    def area_cd_m2(self) -> float:
        """Exposed area times drag coefficient (m^2) for the quadratic body drag."""
        return self._drag_terms()[0]

    @property
    def momentum_drag_factor(self) -> float:
        """SIM_Motor's momentum_drag_factor: mdrag_coef * sqrt(rho * disc area per motor) (sqrt(kg/m))."""
        per_motor_area_m2 = self.disc_area_m2 / len(self.motors_deg_yaw)
        return self._drag_terms()[1] * math.sqrt(self.air_density_kg_m3 * per_motor_area_m2)

    @property
    def motor_positions_frd_m(self) -> tuple[tuple[float, float, float], ...]:
        """Each motor's position in body FRD (m), as SIM_Motor::setup_params."""
        return tuple((math.cos(math.radians(a)) * self.diagonal_size_m,
                      math.sin(math.radians(a)) * self.diagonal_size_m, 0.0) for a, _ in self.motors_deg_yaw)

    # --- ArduPilot's thrust curve ----------------------------------------------------------------

    def pwm_to_command(self, pwm_us: float) -> float:
        """SIM_Motor::pwm_to_command: PWM (us) to a command 0..1 between the spin_min and spin_max PWMs."""
        span = self.pwm_max_us - self.pwm_min_us
        pwm_low = self.pwm_min_us + self.spin_min * span
        pwm_high = self.pwm_min_us + self.spin_max * span
        return min(max((pwm_us - pwm_low) / (pwm_high - pwm_low), 0.0), 1.0)

    def command_to_pwm_us(self, command: float) -> float:
        """The inverse of `pwm_to_command` for a command 0..1 (AP_MotorsMulticopter::output_to_pwm)."""
        span = self.pwm_max_us - self.pwm_min_us
        return self.pwm_min_us + (self.spin_min + command * (self.spin_max - self.spin_min)) * span

    def thrust_fraction(self, command: float) -> float:
        """Static thrust over maximum thrust at `command`: (1-expo) c + expo c^2 (SIM_Motor::calc_thrust),
        the curve AP_MotorsMulticopter's thrust linearisation (MOT_THST_EXPO) inverts."""
        e = self.thrust_expo
        return (1.0 - e) * command + e * command * command

    def command_for_thrust_fraction(self, fraction: float) -> float:
        """The command 0..1 giving `fraction` of maximum static thrust (AP_MotorsMulticopter's curve)."""
        e = self.thrust_expo
        fraction = min(max(fraction, 0.0), 1.0)
        if e <= 0.0:
            return fraction
        return (-(1.0 - e) + math.sqrt((1.0 - e) ** 2 + 4.0 * e * fraction)) / (2.0 * e)

    def hover_pwm_us(self) -> float:
        """The PWM (us) at which four motors at the constant battery voltage lift the weight."""
        voltage_scale = self.battery_voltage_v / self.battery_max_voltage_v
        command = self.command_for_thrust_fraction(self.hover_throttle / voltage_scale ** 2)
        return self.command_to_pwm_us(command)


@dataclass(frozen=True, kw_only=True)
class MultirotorState:
    """One snapshot of the vehicle: time, motion in NED / FRD, attitude, motors, ground contact.

    `quaternion_wxyz` rotates body FRD vectors into NED. `accel_frd_m_s2` is the specific force an
    accelerometer measures (m/s^2, body FRD; (0, 0, -g) at rest, level). `motor_commands` are the
    motors' lagged commands 0..1 in ArduPilot's motor order.
    """

    time_s: float
    position_ned_m: tuple[float, float, float]
    velocity_ned_m_s: tuple[float, float, float]
    quaternion_wxyz: tuple[float, float, float, float]
    gyro_frd_rad_s: tuple[float, float, float]
    accel_frd_m_s2: tuple[float, float, float]
    motor_commands: tuple[float, ...]
    on_ground: bool
    rangefinder_down_m: float

    @property
    def euler_rad(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) in rad, ZYX order, from `quaternion_wxyz`."""
        w, x, y, z = self.quaternion_wxyz
        roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
        pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        return roll, pitch, yaw


def rotation_body_to_ned(w: float, x: float, y: float, z: float) -> tuple[tuple[float, float, float], ...]:
    """The rotation matrix (rows) taking body FRD vectors to NED, from the unit quaternion (w, x, y, z)."""
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
            (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
            (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))


class QuadXMultirotor:
    """The quad X in motion: `step(pwm_us, dt_s)` advances it by `dt_s` simulated seconds.

    The ground is the plane `ground_down_m` (NED down, m); the body origin rests on it. On the ground
    the vehicle does not move (ArduPilot SITL's GROUND_BEHAVIOR_NO_MOVEMENT): no sinking, sliding or
    bouncing, roll and pitch level, until the motors' upward force exceeds the weight.
    `motor_commands` are the motors' commands 0..1 at time 0 (stopped unless given), so a vehicle placed
    in the air can start in hover.
    """

    def __init__(self, *, frame: QuadXFrame | None = None, position_ned_m: Sequence[float] = (0.0, 0.0, 0.0),
                 yaw_rad: float = 0.0, ground_down_m: float = 0.0, rangefinder_max_m: float = 40.0,
                 motor_commands: Sequence[float] | None = None) -> None:
        self.frame = frame or QuadXFrame()
        self.ground_down_m = float(ground_down_m)
        self.rangefinder_max_m = float(rangefinder_max_m)  # reading beyond range or upside down
        self._initial = (tuple(float(v) for v in position_ned_m), float(yaw_rad))
        f = self.frame
        count = len(f.motors_deg_yaw)
        self._initial_commands = [0.0] * count if motor_commands is None else [float(c) for c in motor_commands]
        if len(self._initial_commands) != count:
            raise ValueError(f"motor_commands needs {count} values")
        self._positions = f.motor_positions_frd_m
        self._yaw_factors = tuple(y for _, y in f.motors_deg_yaw)
        self._inertia = f.inertia_kg_m2
        self._max_thrust_n = f.max_thrust_per_motor_n
        self._max_outflow_m_s = f.max_outflow_velocity_m_s
        self._area_cd_m2 = f.area_cd_m2
        self._mdrag = f.momentum_drag_factor
        self._rho = f.air_density_kg_m3
        self._voltage_scale_sq = (f.battery_voltage_v / f.battery_max_voltage_v) ** 2
        self._yaw_scale_m = 0.05 * f.diagonal_size_m  # SIM_Motor: yaw_scale = 0.05 * diagonal_size * thrust
        # SIM_Frame::calculate_forces: rot_accel -= gyro * radians(400) / refRotRate
        self._rot_damping_1_s = math.radians(400.0) / f.ref_rotation_rate_deg_s
        self._lag_dt_s = math.nan  # the step `_lag` and `_slew` were computed for
        self.reset()

    def reset(self) -> None:
        """Back to the initial pose and motor commands, at rest, time 0 (on the ground if placed there)."""
        (n, e, d), yaw = self._initial
        self.time_s = 0.0
        self._p = [n, e, min(d, self.ground_down_m)]
        self._v = [0.0, 0.0, 0.0]
        self._q = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        self._w = [0.0, 0.0, 0.0]
        self._c = list(self._initial_commands)
        self._on_ground = self._p[2] >= self.ground_down_m
        self._f_body = self._rest_specific_force()

    # --- one step -------------------------------------------------------------------------------

    def step(self, pwm_us: Sequence[float], dt_s: float,
             wind_ned_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> MultirotorState:
        """Advance by `dt_s` simulated seconds with motor i+1 at `pwm_us[i]` (us) in air moving at
        `wind_ned_m_s` (NED, m/s: the drag and the rotors see the velocity relative to it); return the
        new state."""
        if dt_s <= 0:
            raise ValueError(f"dt_s must be positive, not {dt_s}")
        f = self.frame
        if dt_s != self._lag_dt_s:  # (the same step each time, from SITL's SIM_RATE_HZ)
            self._lag_dt_s = dt_s
            self._lag = 1.0 if f.motor_time_constant_s <= 0 else 1.0 - math.exp(-dt_s / f.motor_time_constant_s)
            self._slew = f.motor_slew_max_per_s * dt_s if f.motor_slew_max_per_s > 0 else math.inf
        lag, slew = self._lag, self._slew
        for i in range(len(self._c)):
            change = (f.pwm_to_command(pwm_us[i]) - self._c[i]) * lag
            self._c[i] += min(max(change, -slew), slew)  # SIM_Motor's slew limit on the command

        w, x, y, z = self._q
        r = rotation_body_to_ned(w, x, y, z)
        vn, ve, vd = self._v
        if self._on_ground:
            # Resting, the vehicle is held by the ground, not the air (as the embedded simulator's and
            # SITL's GROUND_BEHAVIOR_NO_MOVEMENT): it lifts off on its motors' thrust alone, so a gust
            # cannot bounce a landed vehicle (whose vertical gust vanishes at the ground anyway).
            wind_ned_m_s = (0.0, 0.0, 0.0)
        an_, ae_, ad_ = vn - wind_ned_m_s[0], ve - wind_ned_m_s[1], vd - wind_ned_m_s[2]
        # velocity through the air, in body FRD
        vb = (r[0][0] * an_ + r[1][0] * ae_ + r[2][0] * ad_,
              r[0][1] * an_ + r[1][1] * ae_ + r[2][1] * ad_,
              r[0][2] * an_ + r[1][2] * ae_ + r[2][2] * ad_)
        gx, gy, gz = self._w
        fx = fy = fz = 0.0
        tx = ty = tz = 0.0
        for (px, py, pz), yaw_factor, c in zip(self._positions, self._yaw_factors, self._c):
            # motor velocity through the air: body velocity plus rotation about the centre (gyro x r)
            mvx = vb[0] + gy * pz - gz * py
            mvy = vb[1] + gz * px - gx * pz
            mvz = vb[2] + gx * py - gy * px
            inflow = max(0.0, -mvz)  # air entering the rotor when the motor climbs (SIM_Motor)
            thrust = self._max_thrust_n * (self._voltage_scale_sq * f.thrust_fraction(c)
                                           - (inflow / self._max_outflow_m_s) ** 2)
            k = self._mdrag * math.sqrt(abs(thrust))
            mfx, mfy, mfz = -k * mvx, -k * mvy, -thrust - k * mvz
            fx += mfx
            fy += mfy
            fz += mfz
            tx += py * mfz - pz * mfy
            ty += pz * mfx - px * mfz
            tz += px * mfy - py * mfx + yaw_factor * c * self._yaw_scale_m * thrust
        q_drag = 0.5 * self._rho * self._area_cd_m2
        fx -= q_drag * vb[0] * abs(vb[0])
        fy -= q_drag * vb[1] * abs(vb[1])
        fz -= q_drag * vb[2] * abs(vb[2])
        m = f.mass_kg
        sfx, sfy, sfz = fx / m, fy / m, fz / m  # specific force in FRD
        an = r[0][0] * sfx + r[0][1] * sfy + r[0][2] * sfz
        ae = r[1][0] * sfx + r[1][1] * sfy + r[1][2] * sfz
        ad = r[2][0] * sfx + r[2][1] * sfy + r[2][2] * sfz + GRAVITY_M_S2

        self.time_s += dt_s
        if self._on_ground and ad >= 0.0:
            # resting: the ground takes whatever the motors do not lift
            self._hold_on_ground()
            return self.state

        ixx, iyy, izz = self._inertia
        d = self._rot_damping_1_s
        # Euler's equations (omega x I omega) plus SIM_Frame's rotational damping
        ax_ = (tx - (izz - iyy) * gy * gz) / ixx - gx * d
        ay_ = (ty - (ixx - izz) * gz * gx) / iyy - gy * d
        az_ = (tz - (iyy - ixx) * gx * gy) / izz - gz * d
        self._w = [gx + ax_ * dt_s, gy + ay_ * dt_s, gz + az_ * dt_s]
        self._integrate_attitude(dt_s)
        self._v = [vn + an * dt_s, ve + ae * dt_s, vd + ad * dt_s]
        self._p = [self._p[0] + self._v[0] * dt_s, self._p[1] + self._v[1] * dt_s,
                   self._p[2] + self._v[2] * dt_s]
        self._f_body = [sfx, sfy, sfz]
        self._on_ground = False
        if self._p[2] >= self.ground_down_m:
            self._hold_on_ground()  # touchdown: inelastic, no bounce
        return self.state

    def _integrate_attitude(self, dt_s: float) -> None:
        gx, gy, gz = self._w
        rate = math.sqrt(gx * gx + gy * gy + gz * gz)
        if rate * dt_s < 1e-12:
            return
        half = 0.5 * rate * dt_s
        s = math.sin(half) / rate
        dw, dx, dy, dz = math.cos(half), gx * s, gy * s, gz * s
        w, x, y, z = self._q
        # q <- q (x) dq: the body rotates by gyro * dt about its own axes
        q = [w * dw - x * dx - y * dy - z * dz,
             w * dx + x * dw + y * dz - z * dy,
             w * dy - x * dz + y * dw + z * dx,
             w * dz + x * dy - y * dx + z * dw]
        q0, q1, q2, q3 = q
        norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        self._q = [q0 / norm, q1 / norm, q2 / norm, q3 / norm]

    def _hold_on_ground(self) -> None:
        w, x, y, z = self._q
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        self._q = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        self._p[2] = self.ground_down_m
        self._v = [0.0, 0.0, 0.0]
        self._w = [0.0, 0.0, 0.0]
        self._on_ground = True
        self._f_body = self._rest_specific_force()

    def _rest_specific_force(self) -> list[float]:
        # the ground's reaction: minus gravity, seen in body FRD
        r = rotation_body_to_ned(*self._q)
        return [-r[2][0] * GRAVITY_M_S2, -r[2][1] * GRAVITY_M_S2, -r[2][2] * GRAVITY_M_S2]

    # --- readings -------------------------------------------------------------------------------

    @property
    def height_above_ground_m(self) -> float:
        """The body origin's height above the ground plane (m)."""
        return self.ground_down_m - self._p[2]

    @property
    def velocity_ned_m_s(self) -> tuple[float, float, float]:
        """The velocity over the ground (NED, m/s)."""
        return self._v[0], self._v[1], self._v[2]

    def rangefinder_down_m(self) -> float:
        """A body-down rangefinder's distance to the ground plane (m), `rangefinder_max_m` when none."""
        _, x, y, _ = self._q
        r22 = 1 - 2 * (x * x + y * y)  # rotation_body_to_ned's down-down element
        height_m = self.ground_down_m - self._p[2]
        if r22 <= 0.1:
            return self.rangefinder_max_m
        return min(max(height_m / r22, 0.0), self.rangefinder_max_m)

    @property
    def state(self) -> MultirotorState:
        """A frozen snapshot of the current state."""
        return MultirotorState(
            time_s=self.time_s,
            position_ned_m=(self._p[0], self._p[1], self._p[2]),
            velocity_ned_m_s=(self._v[0], self._v[1], self._v[2]),
            quaternion_wxyz=(self._q[0], self._q[1], self._q[2], self._q[3]),
            gyro_frd_rad_s=(self._w[0], self._w[1], self._w[2]),
            accel_frd_m_s2=(self._f_body[0], self._f_body[1], self._f_body[2]),
            motor_commands=tuple(self._c),
            on_ground=self._on_ground,
            rangefinder_down_m=self.rangefinder_down_m(),
        )
