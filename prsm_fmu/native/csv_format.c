/* Doubles to CSV text: prsm_fmu/csv_format.py's algorithm (its module docstring, steps 1-4)
 * value by value in C, giving the same bytes (tests/test_csv_compiled.py, seeded random cases).
 *
 * Every constant and table comes from the Python module, written into csv_constants.h by
 * prsm_fmu/csv_compiled.py (doubles as exact hexadecimal literals): nothing is defined twice.
 * Compiled with -ffp-contract=off: no fused multiply-add, so Dekker's product and every sum
 * round as numpy's do.
 *
 * What the Python module does with whole arrays is done here per value, in the same order of
 * operations but for the decade's first guess (first_guess: no log10, the same result); the
 * 24-byte layout and the table look-ups of its step 3 become direct writes of the same
 * characters.  Values left to repr (step 4: |x| outside [CSV_LO, CSV_HI) other than
 * zeros, NaN and infinities, and what step 2 did not settle) are not written: their flat index
 * and the output offset where their text goes are returned, and Python splices repr in.
 * NaN and the infinities are written as repr writes them (texts passed from Python).
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "csv_constants.h"

static double as_double(int64_t bits) { double v; memcpy(&v, &bits, 8); return v; }
static int64_t as_bits(double v) { int64_t b; memcpy(&b, &v, 8); return b; }

/* round(a * 10^k) and the signed rest a * 10^k - round(...) [digits], k = 16 - e, j = e +
 * CSV_EOFF (csv_format._digits, operation for operation) */
static inline int64_t digits(double a, long j, double *rest)
{
    const double *row = CSV_P10_ROWS + 4 * j;
    double hi = row[0], bh = row[1], bl = row[2], lo = row[3];
    double p = a * hi;
    double ah = as_double(as_bits(a) & CSV_HIGH27);
    double al = a - ah;
    double err = ah * bh;
    err -= p;
    err += ah * bl;
    err += al * bh;
    err += al * bl;
    err += a * lo;
    double c = rint(err);
    int64_t d = (int64_t)p + (int64_t)c;
    *rest = err - c;
    return d;
}

static long clip(long j) { return j < 0 ? 0 : (j >= CSV_NJ ? CSV_NJ - 1 : j); }

/* the double nearest to 10^m (the table's 10^(16 - e) at 16 - e = m) */
static double pow10_near(long m) { return CSV_P10_ROWS[4 * clip(16 - m + CSV_EOFF)]; }

/* The first guess of j = e + CSV_EOFF: the largest m with a >= (the double nearest to 10^m),
 * from the binary exponent E (E log10 2 truncated: the decade, one below it or, for E < 0, one
 * above it) corrected by two comparisons; the reference takes floor(log10(a) + CSV_EOFF)
 * instead (log10 costs ~15 ns here).  Both guesses are the decade of a or one off, and step 1's
 * redo brings either to the same (d, j); the one double where they could end apart is the
 * double nearest to 10^n when it lies below 10^n (a guess one low could round its 17 digits
 * up to 10^17), and there both guess n (log10's error is far below the gap from n to its
 * neighbouring doubles).  Equal on every power of ten and its neighbours, both paths
 * (tests/test_csv_compiled.py). */
static long first_guess(double a)
{
    int binary = (int)((as_bits(a) >> 52) & 0x7FF) - 1023;
    long m = (long)(binary * CSV_LOG10_2);    /* truncated: floor(...) or one above */
    m -= a < pow10_near(m);                    /* without branches: random data */
    m += a >= pow10_near(m + 1);
    return m + CSV_EOFF;
}

/* csv_format._shortest for one a, CSV_LO <= a < CSV_HI: 17 digits (trailing zeros when 15
 * suffice) in *d17, the exponent index in *jout; returns whether the text passed step 2 */
static int shortest(double a, int64_t *d17, long *jout)
{
    long j = first_guess(a);
    double r;
    int64_t d = digits(a, clip(j), &r);
    if ((uint64_t)(d - CSV_D16) >= (uint64_t)(CSV_D17 - CSV_D16)) {
        j += (d >= CSV_D17) - (d < CSV_D16);
        d = digits(a, clip(j), &r);
        if (d < CSV_D16 || d >= CSV_D17) {
            d = CSV_D16;
            r = INFINITY;
        }
    }
    j = clip(j);
    int64_t gap = as_bits(a) & CSV_EXPONENT_BITS;
    int64_t shift = (int64_t)((as_double(gap) == a) + 53) << 52;
    double limit = as_double(gap - shift);
    limit *= CSV_P10_SAFE[j];
    limit -= CSV_MARGIN;
    int64_t q = d / CSV_DROP;
    double rem = (double)(d - CSV_DROP * q);
    int up = rem + r > CSV_DROP / 2.0;
    double dist = up * (double)CSV_DROP;
    dist -= rem;
    dist -= r;
    int ok15 = fabs(dist) < limit;
    if (ok15)
        d = (q + up) * CSV_DROP;
    if (d == CSV_D17) {
        d = CSV_D16;
        j += 1;
    }
    *d17 = d;
    *jout = j;
    return fabs(r) < limit || ok15;
}

/* two decimal digits of v < 100, as a 16-bit word (the first digit in the low byte) */
static inline uint64_t pair(uint32_t v)
{
    uint16_t w;
    memcpy(&w, CSV_PAIRS + 2 * v, 2);
    return w;
}

/* eight decimal digits of v < 10^8, as an 8-byte word in memory order (little-endian) */
static inline uint64_t eight(uint32_t v)
{
    uint32_t high = v / 10000, low = v % 10000;
    return pair(high / 100) | pair(high % 100) << 16 | pair(low / 100) << 32
           | pair(low % 100) << 48;
}

/* [-]d.ddd (17 digits, trailing zeros and a bare point dropped) then e+XX; returns the end.
 * Few branches: the sign and the exponent's sign by arithmetic; the 16 digits after the
 * point made as two 8-byte words in registers and stored whole, their trailing zeros counted
 * on the words (the last nonzero byte of word ^ "00000000"), not read back from memory */
static char *put_number(char *p, int negative, int64_t d, long j)
{
    *p = '-';
    p += negative;
    int64_t first = d / CSV_D16;
    int64_t rest = d - first * CSV_D16;
    *p++ = (char)('0' + first);
    if (rest) {
        *p++ = '.';
        uint64_t w0 = eight((uint32_t)(rest / 100000000));
        uint64_t w1 = eight((uint32_t)(rest % 100000000));
        memcpy(p, &w0, 8);
        memcpy(p + 8, &w1, 8);
        const uint64_t zeros = 0x3030303030303030u;      /* "00000000" */
        w0 ^= zeros;                                      /* rest != 0: w0 or w1 nonzero */
        w1 ^= zeros;
        p += w1 ? 16 - (__builtin_clzll(w1) >> 3) : 8 - (__builtin_clzll(w0) >> 3);
    }
    long e = j - CSV_EOFF;
    long negative_e = e < 0;
    p[0] = 'e';
    p[1] = (char)('+' + 2 * negative_e);                  /* '+' 43, '-' 45 */
    uint16_t exponent = (uint16_t)pair((uint32_t)(negative_e ? -e : e));
    memcpy(p + 2, &exponent, 2);
    return p + 4;
}

static char *put_text(char *p, const char *text)
{
    size_t n = strlen(text);
    memcpy(p, text, n);
    return p + n;
}

/* Rows row0 .. row0 + rows - 1 of the table whose column c starts at columns[c] with rows
 * strides[c] bytes apart, as CSV lines (',' between values, '\n' after each row) into out
 * (room for rows * cols * CSV_ROW bytes).  A value left to repr writes nothing: its flat index
 * in the block (row * cols + column) goes to left_index[], the offset of its text in out to
 * left_at[], their count to *n_left.  Returns the bytes written.
 *
 * The block is first gathered column by column into the row-major scratch (rows * cols
 * doubles): each column is read as one run of memory, not one value per row from as many
 * places as there are columns.  Then, CHUNK values at a time, the digits of all (steps 1-2)
 * and the texts of all (step 3): two short loops run faster than one long one. */
long csv_format_rows(const char *const *columns, const int64_t *strides, long cols, long row0,
                     long rows, double *scratch, char *out, int64_t *left_index,
                     int64_t *left_at, long *n_left)
{
    for (long c = 0; c < cols; c++) {
        const char *column = columns[c] + row0 * strides[c];
        for (long i = 0; i < rows; i++)
            memcpy(scratch + i * cols + c, column + i * strides[c], 8);
    }
    enum { CHUNK = 256, LEFT = 0, NUMBER = 1, NOT_A_NUMBER = 2, INFINITE = 3 };
    int64_t digits17[CHUNK];
    int32_t exponent[CHUNK];
    int8_t kind[CHUNK];
    char *p = out;
    long left = 0, n = rows * cols, c = 0;        /* c: the column of the next value */
    for (long k0 = 0; k0 < n; k0 += CHUNK) {
        long m = n - k0 < CHUNK ? n - k0 : CHUNK;
        for (long k = 0; k < m; k++) {
            double a = fabs(scratch[k0 + k]);
            uint64_t offset = (uint64_t)(as_bits(a) - CSV_LO_BITS);
            int64_t d = 0;                        /* zeros: 0e+00 */
            long j = CSV_EOFF;
            if (offset < CSV_SPAN_BITS)
                kind[k] = shortest(a, &d, &j) ? NUMBER : LEFT;
            else
                kind[k] = a == 0.0 ? NUMBER : isnan(a) ? NOT_A_NUMBER
                          : isinf(a) ? INFINITE : LEFT;
            digits17[k] = d;
            exponent[k] = (int32_t)j;
        }
        for (long k = 0; k < m; k++) {
            int negative = signbit(scratch[k0 + k]) != 0;
            switch (kind[k]) {
            case NUMBER:
                p = put_number(p, negative, digits17[k], exponent[k]);
                break;
            case NOT_A_NUMBER:
                p = put_text(p, CSV_NAN_TEXT);
                break;
            case INFINITE:
                p = put_text(p, negative ? CSV_NEGATIVE_INF_TEXT : CSV_INF_TEXT);
                break;
            default:
                left_index[left] = k0 + k;
                left_at[left] = p - out;
                left++;
            }
            c++;
            *p++ = c < cols ? ',' : '\n';
            c = c < cols ? c : 0;
        }
    }
    *n_left = left;
    return p - out;
}
