/* The per-step half of bridge.py, in C: the steady-state exchange with no Python on its path.
 *
 * native.py registers bridge_apply_action and bridge_observe as the EnergyPlus callbacks. Until
 * Python arms this bridge they hand each call to the Python Bridge (setup, warmup, sizing, the first
 * exchange); once armed they do what Bridge._apply_action and Bridge._observe do, with the same frames
 * (pipe.py: int32 count, then float64 values; a negative count is a control code) and the same spin
 * (poll the action pipe, yielding the core, for spin_s; then block). No EnergyPlus headers: Python
 * hands over the addresses of the few API functions used, as pyenergyplus has loaded them.
 * Errors cannot cross the callback boundary: they are recorded, EnergyPlus is stopped, and Python
 * reports them after the run (bridge_error).
 */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#define MAX_VALUES 64
#define TIME_FIELDS 4
#define CODE_END (-1)

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "frames are little-endian (pipe.py); this bridge writes them in host order"
#endif

typedef void *State;
typedef void *(*callback_fn)(State); /* as pyenergyplus declares callbacks: void *(*)(void *) */
typedef int (*int_fn)(State);
typedef double (*get_fn)(State, int);
typedef void (*set_fn)(State, int, double);
typedef void (*stop_fn)(State);

struct api {
    get_fn get_variable;
    set_fn set_actuator;
    int_fn year, day_of_year, hour, zone_timestep;
    stop_fn stop;
    int_fn warmup_flag, kind_of_sim, data_ready;
};

#define KIND_RUN_PERIOD_WEATHER 3 /* bridge.py's: kindOfSim during a weather-file run period */

static struct {
    int armed, done, pending;
    int seen_ready; /* EnergyPlus's API data was ready once: until then no call reaches Python (it does nothing) */
    int holding; /* sizing and warm-up: the initial action held and the sensors kept, until the run period */
    double last_obs[MAX_VALUES]; /* while holding: the sensors at the latest zone timestep, for observation 0 */
    int awaiting; /* an observation is out and its action not yet read: it is read where it is applied */
    callback_fn slow_apply, slow_observe; /* the Python Bridge's callbacks, until armed */
    struct api api;
    int obs_fd, act_fd;
    int n_sensors, sensors[MAX_VALUES];
    int n_actuators, actuators[MAX_VALUES], actuator_action[MAX_VALUES];
    int n_actions;
    double action[MAX_VALUES];
    long step, steps;
    const double *replay; /* raw runs only: one action row per step, applied as the env's would be */
    long replay_rows, replayed;
    double done_at;
    double wait_s;  /* blocked on actions: from needing one (where it is applied) to having it */
    double ahead_s; /* from writing an observation to needing its action: EnergyPlus computing meanwhile */
    double sent_at;
    long exchanges, apply_calls, observe_calls;
    int minutes;
    double spin_s;
    unsigned char buf[4 + 8 * MAX_VALUES + 4096];
    size_t got;
    char error[256];
} b;

/* Record the first error and stop EnergyPlus; later calls do nothing. */
static void fail(State state, const char *what) {
    if (!b.error[0])
        snprintf(b.error, sizeof b.error, "%s", what);
    b.api.stop(state);
}

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

/* One write, as pipe.encode builds it: frames stay under PIPE_BUF, so they arrive whole. */
static int write_frame(int32_t code, const double *values, int32_t n) {
    unsigned char out[8 + 8 * (4 + MAX_VALUES)];
    size_t len = 0;
    if (code != 0) {
        memcpy(out, &code, 4);
        len = 4;
    }
    memcpy(out + len, &n, 4);
    memcpy(out + len + 4, values, 8 * (size_t)n);
    len += 4 + 8 * (size_t)n;
    ssize_t w;
    do
        w = write(b.obs_fd, out, len);
    while (w < 0 && errno == EINTR);
    return w == (ssize_t)len ? 0 : -1;
}

/* The next action frame into b.action; FrameReader.read's loop: take what has arrived, spin, block. */
static int read_action(State state) {
    double spin_until = -1.0;
    for (;;) {
        if (b.got >= 4) {
            int32_t count;
            memcpy(&count, b.buf, 4);
            if (count != b.n_actions) {
                char msg[128];
                snprintf(msg, sizeof msg, "expected an action of %d values, got a frame of count %d",
                         b.n_actions, count);
                fail(state, msg);
                return -1;
            }
            size_t end = 4 + 8 * (size_t)count;
            if (b.got >= end) {
                memcpy(b.action, b.buf + 4, 8 * (size_t)count);
                memmove(b.buf, b.buf + end, b.got - end);
                b.got -= end;
                return 0;
            }
        }
        ssize_t r = read(b.act_fd, b.buf + b.got, sizeof b.buf - b.got);
        if (r > 0) {
            b.got += (size_t)r;
        } else if (r == 0) {
            fail(state, "the env closed the action pipe");
            return -1;
        } else if (errno == EAGAIN) {
            double t = now_s();
            if (spin_until < 0)
                spin_until = t + b.spin_s;
            if (t < spin_until) {
                sched_yield();
            } else {
                struct pollfd p = {b.act_fd, POLLIN, 0};
                if (poll(&p, 1, -1) < 0 && errno != EINTR) {
                    fail(state, "poll on the action pipe failed");
                    return -1;
                }
            }
        } else if (errno != EINTR) {
            fail(state, "read from the action pipe failed");
            return -1;
        }
    }
}

/* The action for the observation last written, read where EnergyPlus first needs it: everything EnergyPlus does
 * from the end of one zone timestep up to the next one's actuators (weather, surfaces, the predictor) does not
 * depend on it, so the env's turnaround and the two pipe crossings overlap that work instead of stopping it. */
static int take_action(State state) {
    double t = now_s();
    b.ahead_s += t - b.sent_at;
    if (read_action(state) != 0)
        return -1;
    b.awaiting = 0;
    b.pending = 1;
    b.wait_s += now_s() - t;
    b.exchanges++;
    return 0;
}

/* While holding: what Bridge._apply_action does before the run period (write the held action once per zone
 * timestep); 0 once the run period has begun (Python's first exchange takes over). */
static int hold_apply(State state) {
    if (!(b.api.warmup_flag(state) == 0 && b.api.kind_of_sim(state) == KIND_RUN_PERIOD_WEATHER)) {
        if (b.pending) {
            b.pending = 0;
            for (int i = 0; i < b.n_actuators; i++)
                b.api.set_actuator(state, b.actuators[i], b.action[b.actuator_action[i]]);
        }
        return 1;
    }
    return 0;
}

/* Before the API data is ready the Python Bridge's callbacks return at once (_handles_ready): skip them. */
static int not_ready(State state) {
    if (!b.seen_ready)
        b.seen_ready = b.api.data_ready(state) != 0;
    return !b.seen_ready;
}

void *bridge_apply_action(State state) {
    if (!b.armed) {
        if (b.holding ? hold_apply(state) : not_ready(state))
            return NULL;
        return b.slow_apply(state);
    }
    b.apply_calls++;
    if (b.done || b.error[0])
        return NULL;
    if (b.awaiting && take_action(state) != 0)
        return NULL;
    if (!b.pending)
        return NULL;
    b.pending = 0;
    for (int i = 0; i < b.n_actuators; i++)
        b.api.set_actuator(state, b.actuators[i], b.action[b.actuator_action[i]]);
    return NULL;
}

void *bridge_observe(State state) {
    if (!b.armed) {
        if (!b.holding)
            return not_ready(state) ? NULL : b.slow_observe(state);
        for (int i = 0; i < b.n_sensors; i++) /* Bridge._observe before the run: keep the state, re-assert */
            b.last_obs[i] = b.api.get_variable(state, b.sensors[i]);
        b.pending = 1;
        return NULL;
    }
    b.observe_calls++;
    if (b.done || b.error[0])
        return NULL;
    if (b.awaiting && take_action(state) != 0) /* no actuator call since the last observation: one frame each */
        return NULL;
    double values[TIME_FIELDS + MAX_VALUES];
    values[0] = b.api.year(state);
    values[1] = b.api.day_of_year(state);
    values[2] = b.api.hour(state);
    values[3] = (double)b.api.zone_timestep(state) * b.minutes;
    for (int i = 0; i < b.n_sensors; i++)
        values[TIME_FIELDS + i] = b.api.get_variable(state, b.sensors[i]);
    int n = TIME_FIELDS + b.n_sensors;
    b.step++;
    if (b.step >= b.steps) {
        b.done = 1;
        b.done_at = now_s();
        if (b.obs_fd < 0) /* raw: the rest of the day would run under the last action; nobody wants it */
            b.api.stop(state);
        else if (write_frame(CODE_END, values, n) < 0)
            fail(state, "cannot write the last observation");
        return NULL;
    }
    if (b.obs_fd < 0) { /* raw: EnergyPlus alone, the initial action held or the replay's next row */
        if (b.replayed < b.replay_rows) {
            memcpy(b.action, b.replay + b.replayed * b.n_actions, sizeof(double) * (size_t)b.n_actions);
            b.replayed++;
            b.pending = 1;
        }
        return NULL;
    }
    if (write_frame(0, values, n) < 0) {
        fail(state, "cannot write an observation: the env is gone");
        return NULL;
    }
    b.sent_at = now_s();
    b.awaiting = 1;
    return NULL;
}

/* Before the run: where to hand calls until armed, and the API functions to use once armed. */
void bridge_init(callback_fn slow_apply, callback_fn slow_observe, get_fn get_variable, set_fn set_actuator,
                 int_fn year, int_fn day_of_year, int_fn hour, int_fn zone_timestep, stop_fn stop,
                 int_fn warmup_flag, int_fn kind_of_sim, int_fn data_ready) {
    memset(&b, 0, sizeof b);
    b.slow_apply = slow_apply;
    b.slow_observe = slow_observe;
    b.api = (struct api){get_variable, set_actuator, year, day_of_year, hour, zone_timestep, stop, warmup_flag,
                         kind_of_sim, data_ready};
}

/* The handles and the action both entries take over from Python; -1 when a count or an index is out of range. */
static int take_handles(int n_sensors, const int *sensors, int n_actuators, const int *actuators,
                        const int *actuator_action, int n_actions, const double *action, int pending) {
    if (n_sensors > MAX_VALUES || n_actuators > MAX_VALUES || n_actions > MAX_VALUES)
        return -1;
    for (int i = 0; i < n_actuators; i++)
        if (actuator_action[i] < 0 || actuator_action[i] >= n_actions)
            return -1;
    b.n_sensors = n_sensors;
    memcpy(b.sensors, sensors, sizeof(int) * (size_t)n_sensors);
    b.n_actuators = n_actuators;
    memcpy(b.actuators, actuators, sizeof(int) * (size_t)n_actuators);
    memcpy(b.actuator_action, actuator_action, sizeof(int) * (size_t)n_actuators);
    b.n_actions = n_actions;
    memcpy(b.action, action, sizeof(double) * (size_t)n_actions);
    b.pending = pending;
    return 0;
}

/* Sizing and warm-up in C (~2,700 Python callbacks an episode, ~5-10 ms, before: issue 39): from the first call
 * with the handles known until the run period's first control step, which goes back to Python with the state
 * (bridge_unhold). */
int bridge_hold(int n_sensors, const int *sensors, int n_actuators, const int *actuators,
                const int *actuator_action, int n_actions, const double *action, int pending,
                const double *last_obs) {
    if (take_handles(n_sensors, sensors, n_actuators, actuators, actuator_action, n_actions, action, pending) < 0)
        return -1;
    memcpy(b.last_obs, last_obs, sizeof(double) * (size_t)n_sensors);
    b.holding = 1;
    return 0;
}

/* Back to Python: the latest sensors into `last_obs`; returns whether the held action is still to be written. */
int bridge_unhold(double *last_obs) {
    b.holding = 0;
    memcpy(last_obs, b.last_obs, sizeof(double) * (size_t)b.n_sensors);
    return b.pending;
}

/* Take over from Python after its first exchange: from here on every call stays in C. */
int bridge_arm(int obs_fd, int act_fd, int n_sensors, const int *sensors, int n_actuators,
               const int *actuators, const int *actuator_action, int n_actions, const double *action,
               int pending, long step, long steps, int minutes, double spin_s, const double *replay,
               long replay_rows, long replayed) {
    if (take_handles(n_sensors, sensors, n_actuators, actuators, actuator_action, n_actions, action, pending) < 0)
        return -1;
    b.obs_fd = obs_fd;
    b.act_fd = act_fd;
    if (act_fd >= 0 && spin_s <= 0) { /* no spin: one blocking read per action, no failed read and poll first */
        int flags = fcntl(act_fd, F_GETFL);
        if (flags < 0 || fcntl(act_fd, F_SETFL, flags & ~O_NONBLOCK) < 0)
            return -1;
    }
    b.step = step;
    b.steps = steps;
    b.minutes = minutes;
    b.spin_s = spin_s;
    b.replay = replay;
    b.replay_rows = replay_rows;
    b.replayed = replayed;
    b.armed = 1;
    return 0;
}

long bridge_step(void) { return b.step; }
double bridge_wait_s(void) { return b.wait_s; }
double bridge_ahead_s(void) { return b.ahead_s; }
long bridge_exchanges(void) { return b.exchanges; }
long bridge_apply_calls(void) { return b.apply_calls; }
long bridge_observe_calls(void) { return b.observe_calls; }
int bridge_done(void) { return b.done; }
double bridge_done_at(void) { return b.done_at; }
int bridge_armed(void) { return b.armed; }
const char *bridge_error(void) { return b.error; }
