/*
 * ehss_compensator.h - the compensator filter of a real-time target, and the decoder of
 * the datagram that carries a compensator to it (ehss, BSD-3-Clause).
 *
 * Portable C99: no allocation, no libc beyond <string.h>, <stdint.h> and <math.h>
 * (sqrt, log and ceil, when an update is taken up: link with the maths library, -lm),
 * fixed-size state. Doubles must be IEEE-754 binary64 (checked at compile time by size).
 * Reference: the Python package ehss.target (filter.py, datagram.py) does the same
 * arithmetic in the same order; the tests of ehss compile this file and compare both.
 *
 * One ehss_comp_state per channel:
 *
 *     ehss_comp_init(&s, channel, preview, fs_hz, first_sample_index);   once
 *     ehss_comp_decode(&s, bytes, n_bytes);   whenever a datagram arrives
 *                                             (a non-real-time thread may call it)
 *     drive = ehss_comp_step(&s, r_ahead);    once per control period, where r_ahead
 *                                             is the reference `preview` samples ahead
 *
 * The filter: second-order sections (b0 b1 b2 a0 a1 a2, a0 = 1, direct form II
 * transposed) then an FIR part. A decoded update waits in a one-slot mailbox; the step
 * takes it up at a sample boundary outside a cross-fade and runs it in shadow from its
 * zero state; from its apply index k0 the output is (1 - w) old + w new with
 * w = (k - k0 + 1) / N, and after sample k0 + N - 1 (w = 1) the old filter is dropped.
 * An update always runs in shadow for its settling time (ehss_comp_settle_samples):
 * one taken up too late for that before k0 starts its cross-fade that long after it
 * was taken up instead (counted `late`), so no start-up transient reaches the drive.
 *
 * Threads: ehss_comp_decode writes only the state's scratch, mailbox and decode
 * counters; ehss_comp_step reads the mailbox only while `mailbox_full` is set and
 * clears it when done. Between the two, EHSS_COMP_BARRIER() orders the memory accesses
 * (a full fence with GCC/Clang; define it for other compilers when the two calls run
 * on different cores). On a single core, or when both are called from the same task,
 * nothing more is needed.
 */
#ifndef EHSS_COMPENSATOR_H
#define EHSS_COMPENSATOR_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define EHSS_COMP_MAX_SECTIONS 16
/* The FIR's capacity: 0.41 s at 5 kHz (ehss designs 0.256 s of taps by default). A
 * target short of memory may define it lower before including this header, and give
 * `ehss live --taps` at most as many. */
#ifndef EHSS_COMP_MAX_TAPS
#define EHSS_COMP_MAX_TAPS 2048
#endif
#define EHSS_COMP_MAX_PREVIEW (EHSS_COMP_MAX_TAPS - 1)
#define EHSS_COMP_VERSION 1
/* 52 + 48 * 16 + 8 * EHSS_COMP_MAX_TAPS (17 204 bytes at 2048 taps) */
#define EHSS_COMP_MAX_DATAGRAM_BYTES (52 + 48 * EHSS_COMP_MAX_SECTIONS + 8 * EHSS_COMP_MAX_TAPS)
/* largest relative difference of a compensator's sample rate from the channel's */
#define EHSS_COMP_SAMPLE_RATE_TOLERANCE 1e-3

/* What ehss_comp_decode made of a datagram (ehss.target.RESULTS, same order). */
enum ehss_comp_result {
    EHSS_COMP_OK = 0,
    EHSS_COMP_FAULT_TRUNCATED = 1,      /* shorter than its counts say */
    EHSS_COMP_FAULT_MAGIC = 2,
    EHSS_COMP_FAULT_VERSION = 3,
    EHSS_COMP_FAULT_SECTIONS = 4,       /* more than EHSS_COMP_MAX_SECTIONS */
    EHSS_COMP_FAULT_TAPS = 5,           /* 0 or more than EHSS_COMP_MAX_TAPS */
    EHSS_COMP_FAULT_LENGTH = 6,         /* longer than its counts say */
    EHSS_COMP_FAULT_CHECKSUM = 7,
    EHSS_COMP_FAULT_SAMPLE_RATE = 8,    /* not finite or outside 1e-9 .. 1e9 Hz */
    EHSS_COMP_FAULT_PREVIEW = 9,        /* above EHSS_COMP_MAX_PREVIEW */
    EHSS_COMP_FAULT_NON_FINITE = 10,    /* a NaN or infinite coefficient */
    EHSS_COMP_FAULT_NOT_NORMALISED = 11, /* a section's a0 is not 1 */
    EHSS_COMP_FAULT_UNSTABLE = 12,      /* a pole on or outside the unit circle */
    EHSS_COMP_STALE = 13,               /* sequence not above the last one loaded */
    EHSS_COMP_OTHER_CHANNEL = 14,       /* for another channel's state */
    EHSS_COMP_OTHER_PREVIEW = 15,       /* preview differs from the running one */
    EHSS_COMP_BUSY = 16,                /* an update still waits: send it again later */
    EHSS_COMP_OTHER_SAMPLE_RATE = 17,   /* designed for another sample rate */
    EHSS_COMP_N_RESULTS = 18
};

/* One compensator and when it applies: what a datagram carries. */
typedef struct {
    uint16_t channel;
    uint64_t sequence;
    double fs_hz;
    uint64_t apply_index;
    uint32_t crossfade;
    uint32_t preview;
    uint32_t n_sections;
    double sos[EHSS_COMP_MAX_SECTIONS][6];
    uint32_t n_taps;
    double taps[EHSS_COMP_MAX_TAPS];
} ehss_comp_update;

/* One running filter: coefficients and state. */
typedef struct {
    uint32_t n_sections;
    uint32_t n_taps;
    double sos[EHSS_COMP_MAX_SECTIONS][6];
    double taps[EHSS_COMP_MAX_TAPS];
    double z[EHSS_COMP_MAX_SECTIONS][2];   /* each section's two delay states */
    double hist[EHSS_COMP_MAX_TAPS];       /* the sections' last outputs, circular */
    uint32_t pos;                          /* hist[pos] is the newest */
} ehss_comp_slot;

typedef struct {
    /* written by ehss_comp_step */
    uint32_t loads;        /* updates taken up */
    uint32_t swaps;        /* cross-fades completed */
    uint32_t superseded;   /* replaced by a newer update while still in shadow */
    uint32_t late;         /* taken up after their apply index */
    /* written by ehss_comp_decode: datagrams by result */
    uint32_t decoded[EHSS_COMP_N_RESULTS];
} ehss_comp_counters;

typedef struct {
    uint16_t channel;
    uint32_t preview;
    double fs_hz;                /* the channel's sample rate, Hz */
    uint64_t index;              /* sample index of the next drive sample */
    ehss_comp_slot slot[2];
    int run;                     /* slot[run] runs; slot[1 - run] is the next one */
    int has_next;
    uint64_t start;              /* k0 of the next filter */
    uint32_t crossfade;          /* N of the next filter */
    ehss_comp_update scratch;    /* ehss_comp_decode's own */
    ehss_comp_update mailbox;    /* handed over when mailbox_full is set */
    volatile int mailbox_full;
    int has_sequence;
    uint64_t last_sequence;      /* of the last update put in the mailbox */
    ehss_comp_counters counters;
} ehss_comp_state;

/* Start a channel running at `fs_hz`: no compensation (the drive is the reference,
 * i.e. the input delayed by `preview` samples) from sample `start_index`. Returns
 * EHSS_COMP_OK, EHSS_COMP_FAULT_PREVIEW if preview > EHSS_COMP_MAX_PREVIEW or
 * EHSS_COMP_FAULT_SAMPLE_RATE if fs_hz is not finite or outside 1e-9 .. 1e9 Hz. */
int ehss_comp_init(ehss_comp_state *s, uint16_t channel, uint32_t preview, double fs_hz,
                   uint64_t start_index);

/* Parse and check a datagram into `out` without reading beyond buf[0 .. len - 1].
 * Returns EHSS_COMP_OK or the first fault (1 .. 12). */
int ehss_comp_parse(const unsigned char *buf, size_t len, ehss_comp_update *out);

/* The channel a datagram is for, or -1 if it is too short or not one of ours: to
 * route it to its channel's state. */
long ehss_comp_datagram_channel(const unsigned char *buf, size_t len);

/* Parse a datagram and, if it is whole, for this channel, preview and sample rate,
 * newer than the last one and the mailbox is free, put it in the mailbox. Counted by result in
 * s->counters.decoded; returns the result (enum ehss_comp_result). */
int ehss_comp_decode(ehss_comp_state *s, const unsigned char *buf, size_t len);

/* Samples a filter of `n_sections` sections `sos` (a0 = 1, stable) and `n_taps` FIR
 * taps, started at rest, needs to forget its start: n_taps plus 7 / (-ln r), r the
 * largest pole radius of the sections (rounded up). The rule of ehss._settle. */
uint64_t ehss_comp_settle_samples(uint32_t n_sections, const double (*sos)[6],
                                  uint32_t n_taps);

/* One control period: input x = the reference `preview` samples ahead; returns the
 * drive of this sample. Takes up a waiting update first (outside a cross-fade). */
double ehss_comp_step(ehss_comp_state *s, double x);

#ifdef __cplusplus
}
#endif

#endif /* EHSS_COMPENSATOR_H */
