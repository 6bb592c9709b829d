"""The fixed C of an exported Kilobot program (`kilobot.py` writes the rest from the
checked program): helpers for the language's numbers, vectors and messages, the motion
of a robot turning its own way, trilateration, and the steering of a robot with beliefs.
Nothing here depends on a program's text."""

PREAMBLE = """\
#if defined(__AVR__) || defined(KILOLIB_API)   /* the robot, or a harness of its API */
#define KB_KILOLIB 1
#endif
#ifdef KB_KILOLIB
#include "kilolib_api.h"
#else
#include <kilombo.h>
#include <jansson.h>
#endif
#include <math.h>
#include <stdint.h>

#define KB_TABLE {table}          /* neighbours remembered */
#define KB_STEP_TICKS {step}     /* kilo_ticks per program tick (0.1 s) */
#define KB_HEARD_TICKS {heard}   /* a neighbour unheard this long is forgotten */
#define KB_SEND_WINDOW {window}   /* program ticks a broadcast keeps being sent */

/* The language's operators and functions where C's differ on edge values (each row
 * checked against swarmdsl/ops on them): `%` floored as numpy's (7 % inf is 7, x % 0
 * NaN), `min`/`max` carrying a NaN, `sign` of NaN NaN, `round` half to even exactly. */
static inline float kb_mod(float a, float b) {{
    float r = fmodf(a, b);
    if (r != 0.0f) {{
        if ((r < 0.0f) != (b < 0.0f)) r += b;
    }} else {{
        r = copysignf(0.0f, b);
    }}
    return r;
}}
static inline float kb_min(float a, float b) {{ return a != a ? a : b != b ? b : a < b ? a : b; }}
static inline float kb_max(float a, float b) {{ return a != a ? a : b != b ? b : a > b ? a : b; }}
static inline float kb_pow(float a, float b) {{ return powf(a, b); }}
static inline float kb_sign(float x) {{ return x != x ? x : (float)((x > 0) - (x < 0)); }}
static inline float kb_clamp(float x, float lo, float hi) {{ return kb_min(kb_max(x, lo), hi); }}
static inline float kb_round(float x) {{   /* half to even, as the language rounds */
    if (!(fabsf(x) < 8388608.0f)) return x;   /* whole already, inf or NaN */
    float r = floorf(x), d = x - r;          /* d is exact */
    if (d > 0.5f || (d == 0.5f && fmodf(r, 2.0f) != 0.0f)) r += 1.0f;
    return r;
}}

static inline uint8_t kb_channel(float c) {{   /* 0..1 -> kilolib's 0..3 */
    if (!(c > 0.0f)) return 0;
    if (c >= 1.0f) return 3;
    return (uint8_t)(c * 3.0f + 0.5f);
}}
static inline uint8_t kb_rgb(float r, float g, float b) {{
    return RGB(kb_channel(r), kb_channel(g), kb_channel(b));
}}
static inline void kb_pack(uint8_t *p, float v) {{   /* a number: a rounded int16 */
    int16_t w = v >= 32767.0f ? 32767 : v <= -32768.0f ? -32768 : (int16_t)lroundf(v);
    p[0] = (uint8_t)(w & 0xFF);
    p[1] = (uint8_t)(((uint16_t)w >> 8) & 0xFF);
}}
static inline float kb_unpack(const uint8_t *p) {{
    return (float)(int16_t)((uint16_t)p[0] | ((uint16_t)p[1] << 8));
}}

/* A vector: two floats. The language's vector functions, as its definitions: the zero
 * vector normalised stays zero. */
typedef struct {{ float x, y; }} kb_vec_t;
static inline kb_vec_t kb_v(float x, float y) {{ kb_vec_t v = {{ x, y }}; return v; }}
static inline kb_vec_t kb_vadd(kb_vec_t a, kb_vec_t b) {{ return kb_v(a.x + b.x, a.y + b.y); }}
static inline kb_vec_t kb_vsub(kb_vec_t a, kb_vec_t b) {{ return kb_v(a.x - b.x, a.y - b.y); }}
static inline kb_vec_t kb_vmul(kb_vec_t a, float s) {{ return kb_v(a.x * s, a.y * s); }}
static inline kb_vec_t kb_vdiv(kb_vec_t a, float s) {{ return kb_v(a.x / s, a.y / s); }}
static inline kb_vec_t kb_vneg(kb_vec_t a) {{ return kb_v(-a.x, -a.y); }}
static inline float kb_vlen(kb_vec_t a) {{   /* the language's sqrt(x^2 + y^2): NaN in, NaN out */
    return (a.x != a.x || a.y != a.y) ? a.x + a.y : hypotf(a.x, a.y);
}}
static inline float kb_vdist(kb_vec_t a, kb_vec_t b) {{ return kb_vlen(kb_vsub(a, b)); }}
static inline float kb_vdot(kb_vec_t a, kb_vec_t b) {{ return a.x * b.x + a.y * b.y; }}
static inline float kb_vcross(kb_vec_t a, kb_vec_t b) {{ return a.x * b.y - a.y * b.x; }}
static inline float kb_vangle(kb_vec_t a) {{ return atan2f(a.y, a.x); }}
static inline kb_vec_t kb_unit(float a) {{ return kb_v(cosf(a), sinf(a)); }}
static inline kb_vec_t kb_vnorm(kb_vec_t a) {{
    float n = kb_vlen(a);
    return n > 0.0f ? kb_vdiv(a, n) : kb_v(0.0f, 0.0f);
}}
static inline kb_vec_t kb_vrot(kb_vec_t a, float t) {{   /* counter-clockwise */
    float c = cosf(t), s = sinf(t);
    return kb_v(c * a.x - s * a.y, s * a.x + c * a.y);
}}
"""



def preamble(table: int = 8, step: int = 3, heard: int = 40, window: int = 5) -> str:
    """The preamble with its constants (the exporter's; the defaults are its own), then
    the C helpers the language's rows bring with their forms (`row_helpers`)."""
    return PREAMBLE.format(table=table, step=step, heard=heard, window=window) + \
        row_helpers()


def row_helpers() -> str:
    """The C helper functions function and operator rows declare beside their forms
    (`kilobot_helper`: a form that needs more than an expression), once each in the
    rows' order, so a new row's C is written in its row alone."""
    from swarmdsl.ops.functions import FUNCTIONS
    from swarmdsl.ops.operators import ARITHMETIC, COMPARISONS, NEGATE

    rows = (*FUNCTIONS.values(), *ARITHMETIC.values(), *COMPARISONS.values(), NEGATE)
    return "".join(dict.fromkeys(r.kilobot_helper for r in rows if r.kilobot_helper))


RANDOM = """\
/* Each robot's own random stream: a 32-bit xorshift generator in its state, seeded in
 * setup() from the robot's hardware entropy (rand_hard: the noise of its own battery
 * voltage on a Kilobot; Kilombo's shared generator in the simulator) and its id, so no
 * two robots draw alike (the state is the robot's: Kilombo runs every robot in one
 * process). kilolib's rand_soft() has 8 bits of state (256 streams at most)
 * and steps of 1/256; these draws have steps of 2^-24. */
static inline uint32_t kb_next(void) {
    uint32_t x = mydata->rng;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    return mydata->rng = x;
}
static void kb_seed(uint16_t uid) {
    uint32_t s = (uint32_t)uid * 0x9E3779B9u;
    for (uint8_t i = 0; i < 4; i++) s ^= (uint32_t)rand_hard() << (8 * i);
    s ^= s >> 16;
    s *= 0x85EBCA6Bu;
    s ^= s >> 13;
    mydata->rng = s ? s : 0x6D2B79F5u;
    rand_seed((uint8_t)kb_next());    /* kilolib's own generator too, for its users */
}
static inline float kb_random(void) { return (float)(kb_next() >> 8) * (1.0f / 16777216.0f); }
static inline float kb_uniform(float lo, float hi) { return lo + kb_random() * (hi - lo); }
static inline uint8_t kb_chance(float p) { return kb_random() < p; }
"""


MOTION = """\
enum { KB_STOP, KB_STRAIGHT, KB_LEFT, KB_RIGHT };

/* A turn relative to the robot's own motion: left for a positive angle, right for a
 * negative one, straight for 0 (the angle's size is the robot's calibrated turn). */
static inline void kb_turn(float angle)
{
    if (!mydata->moving) return;
    mydata->motion = angle > 0 ? KB_LEFT : angle < 0 ? KB_RIGHT : KB_STRAIGHT;
}

/* A motion command (stop(), forward(), turn_left(), turn_right()): the robot moves
 * so until another command, or goes straight on from a turn. */
static inline void kb_command(uint8_t motion)
{
    mydata->moving = motion != KB_STOP;
    mydata->motion = motion;
}
static inline uint8_t kb_side(float rate)   /* a turn of this sign; none: standing */
{
    return rate > 0 ? KB_LEFT : rate < 0 ? KB_RIGHT : KB_STOP;
}

/* The motors for a motion, with kilolib's calibrated duty cycles. kilolib asks for a
 * spin-up (both motors at full power for 15 ms, to overcome static friction) whenever
 * a motor starts from off: a start from rest, a turn becoming straight, a turn to the
 * other side. Going from straight to a turn only stops a motor: no spin-up. */
#define KB_LEFT_ON(m) ((m) == KB_STRAIGHT || (m) == KB_LEFT)
#define KB_RIGHT_ON(m) ((m) == KB_STRAIGHT || (m) == KB_RIGHT)
static void kb_motors(uint8_t motion)
{
    uint8_t was = mydata->motors;
    if (motion == was) return;
    if ((KB_LEFT_ON(motion) && !KB_LEFT_ON(was)) || (KB_RIGHT_ON(motion) && !KB_RIGHT_ON(was)))
        spinup_motors();
    mydata->motors = motion;
    switch (motion) {
    case KB_STRAIGHT: set_motors(kilo_straight_left, kilo_straight_right); break;
    case KB_LEFT: set_motors(kilo_turn_left, 0); break;
    case KB_RIGHT: set_motors(0, kilo_turn_right); break;
    default: set_motors(0, 0);
    }
}

"""

TRILATERATION = r"""
/* Trilateration, as the language's `trilaterate`: a fix is (pos, ok); no fix (fewer
 * than three references, or references on one line) is ((0, 0), 0). */
typedef struct { kb_vec_t pos; uint8_t ok; } kb_fix_t;
#define KB_REFERENCES 6   /* the nearest references a fix is taken from */
/* The flattest triangle of references a fix is taken from (the sine of the angle
 * between two sides): the language needs only a triangle that is not a line, as its
 * references' positions and distances are exact; a robot's are off by a millimetre or
 * so, and three robots of a row, a few millimetres out of line, would give a fix tens
 * of millimetres off. */
#define KB_MIN_SINE 0.2f

/* The linear system of three references, solved relative to the first. */
static kb_fix_t kb_solve3(kb_vec_t p1, float r1, kb_vec_t p2, float r2, kb_vec_t p3, float r3)
{
    kb_fix_t fix = { { 0.0f, 0.0f }, 0 };
    kb_vec_t q2 = kb_vsub(p2, p1), q3 = kb_vsub(p3, p1);
    float a = q2.x, b = q2.y, d = q3.x - q2.x, e = q3.y - q2.y;
    float c = (r1 * r1 - r2 * r2 + q2.x * q2.x + q2.y * q2.y) / 2;
    float f = (r2 * r2 - r3 * r3 - q2.x * q2.x + q3.x * q3.x - q2.y * q2.y + q3.y * q3.y) / 2;
    float den = b * d - a * e;
    float scale = hypotf(a, b) * hypotf(d, e);
    if (!(scale > 0.0f) || !(fabsf(den) > 1e-6f * scale) || !isfinite(c) || !isfinite(f))
        return fix;
    fix.pos = kb_vadd(p1, kb_v((b * f - c * e) / den, (c * d - a * f) / den));
    fix.ok = 1;
    return fix;
}

/* A fix from n references (points p, measured distances r): of the nearest
 * KB_REFERENCES, the triple whose triangle is least degenerate (largest |det|), if
 * any is no flatter than KB_MIN_SINE. */
static kb_fix_t kb_trilaterate(const kb_vec_t *p, const float *r, uint8_t n)
{
    uint8_t near[KB_REFERENCES], m = 0;
    for (uint8_t i = 0; i < n; i++) {   /* insertion by distance, the nearest kept */
        uint8_t j = m < KB_REFERENCES ? m++ : KB_REFERENCES;
        while (j > 0 && r[near[j - 1]] > r[i]) {
            if (j < KB_REFERENCES) near[j] = near[j - 1];
            j--;
        }
        if (j < KB_REFERENCES) near[j] = i;
    }
    float best = -1.0f;
    uint8_t ba = 0, bb = 0, bc = 0;
    for (uint8_t a = 0; a < m; a++)
        for (uint8_t b = a + 1; b < m; b++)
            for (uint8_t c = b + 1; c < m; c++) {
                kb_vec_t u = kb_vsub(p[near[b]], p[near[a]]);
                kb_vec_t v = kb_vsub(p[near[c]], p[near[b]]);
                float det = fabsf(kb_vcross(u, v));
                if (det > KB_MIN_SINE * kb_vlen(u) * kb_vlen(v) && det > best) {
                    best = det; ba = near[a]; bb = near[b]; bc = near[c];
                }
            }
    if (best < 0.0f) {
        kb_fix_t none = { { 0.0f, 0.0f }, 0 };
        return none;
    }
    return kb_solve3(p[ba], r[ba], p[bb], r[bb], p[bc], r[bc]);
}
"""

STEERING = r"""
/* Steering (a program with beliefs). `velocity = V` is a displacement per tick in the
 * believed frame: the belief moves by it, as the language's odometry moves it, and so
 * does the goal the motors carry the body to. The robot knows its body only by dead
 * reckoning: its heading from where it was put down (bots.json), then its calibrated
 * speed going straight and turn rate pivoting on a rear leg. Each tick it turns toward
 * the goal until it faces it, goes straight, and stops within KB_NEAR of it: a Kilobot
 * cannot go backward or sideways, only forward and turn. */
#ifndef KB_SPEED
#define KB_SPEED 7.0f          /* mm/s going straight (Kilombo's; measure a real robot's) */
#endif
#ifndef KB_TURN_RATE
#define KB_TURN_RATE 13.0f     /* degrees/s turning on one motor (Kilombo's) */
#endif
#define KB_PIVOT 17.0f         /* mm from the centre to the leg a turn pivots on */
#define KB_LEG 2.19039f        /* the rear legs' angle from the front: 125.5 degrees */
#define KB_NEAR 1.0f           /* mm: a body this close to its goal stops */
#define KB_AIM 0.2f            /* radians off the goal's bearing that ask for a turn */
#ifndef KB_SLACK
#define KB_SLACK 6.0f          /* mm: a goal this near is not turned to (see kb_steer) */
#endif
#define KB_PI 3.14159265f

static inline float kb_wrap(float a)   /* to -pi..pi */
{
    while (a > KB_PI) a -= 2 * KB_PI;
    while (a < -KB_PI) a += 2 * KB_PI;
    return a;
}

/* Dead reckoning of the motion the motors ran since the last call. */
static void kb_odometry(void)
{
    float dt = (float)(uint32_t)(kilo_ticks - mydata->moved_at) / 31.0f;
    mydata->moved_at = kilo_ticks;
    if (mydata->motors == KB_STRAIGHT) {
        mydata->body = kb_vadd(mydata->body, kb_vmul(kb_unit(mydata->head), KB_SPEED * dt));
    } else if (mydata->motors == KB_LEFT || mydata->motors == KB_RIGHT) {
        float side = mydata->motors == KB_LEFT ? KB_LEG : -KB_LEG;
        kb_vec_t pivot = kb_vadd(mydata->body, kb_vmul(kb_unit(mydata->head + side), KB_PIVOT));
        float turn = KB_TURN_RATE * (KB_PI / 180) * dt;
        mydata->head = kb_wrap(mydata->head + (mydata->motors == KB_LEFT ? turn : -turn));
        mydata->body = kb_vsub(pivot, kb_vmul(kb_unit(mydata->head + side), KB_PIVOT));
    }
}

/* The motion that carries the body toward its goal (going straight keeps a little
 * more slack than starting to, so the robot does not hunt left and right). A goal within
 * KB_SLACK more than 45 degrees off its heading is close enough: a turn swings the robot
 * round its leg (a quarter turn about 24 mm), further than the goal is, and chasing it
 * would go on. */
static uint8_t kb_steer(void)
{
    kb_vec_t e = kb_vsub(mydata->goal, mydata->body);
    float d = kb_vlen(e);
    if (d < KB_NEAR) return KB_STOP;
    float off = kb_wrap(kb_vangle(e) - mydata->head);
    float aim = mydata->motors == KB_STRAIGHT ? 2 * KB_AIM : KB_AIM;
    if (fabsf(off) <= aim) return KB_STRAIGHT;
    if (d < KB_SLACK && fabsf(off) > KB_PI / 4) return KB_STOP;
    return off > 0 ? KB_LEFT : KB_RIGHT;
}

/* The commanded velocity within the kind's speed, as the language limits it. */
static inline kb_vec_t kb_limit(kb_vec_t v, float top)
{
    float n = kb_vlen(v);
    return n > top ? kb_vmul(v, top / n) : v;
}
"""
