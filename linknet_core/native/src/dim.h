/* Included first by dim2.c and dim3.c, which define DIM: FN(name) names the DIM copy of a stage. */
#ifndef DIM
#error "DIM must be defined (dim2.c, dim3.c)"
#endif
#if DIM == 2
#define FN(name) name##_2d
#elif DIM == 3
#define FN(name) name##_3d
#else
#error "DIM must be 2 or 3"
#endif

/* Around the stages whose loops run over a scene's K masses or L links a few times per RATTLE stage (the
   projections, the RATTLE loop): on small scenes the checks GCC's loop vectorizer puts before each of those
   loops (aliasing, trip count) cost more than the vectorized loops save, and from about a hundred links on
   the time is in the tension solves. Clang does not vectorize them that way. */
/* The hot path of a small scene's step is a handful of stage calls around loops of a few iterations: the calls
   themselves would cost as much as the work, so the hot parts are inlined into the step loop (LN_ALWAYS_INLINE)
   and the rarely taken recoveries kept out of line (LN_NOINLINE), which keeps the inlined code small. Not marked
   cold: GCC optimises cold functions for size, and a run through a whip spends most of its time in them (split
   steps, exact Newton: 12 % slower so). */
#if defined(__GNUC__) || defined(__clang__)
#define LN_ALWAYS_INLINE static inline __attribute__((always_inline))
#define LN_NOINLINE static __attribute__((noinline))
#define LN_COLD static __attribute__((noinline, cold))  /* once per failure, never in a loop (optimised for size) */
#else
#define LN_ALWAYS_INLINE static inline
#define LN_NOINLINE static
#define LN_COLD static
#endif

#if defined(__GNUC__) && !defined(__clang__)
#define LN_SCALAR_LOOPS_BEGIN _Pragma("GCC push_options") _Pragma("GCC optimize(\"no-tree-loop-vectorize\")")
#define LN_SCALAR_LOOPS_END _Pragma("GCC pop_options")
#else
#define LN_SCALAR_LOOPS_BEGIN
#define LN_SCALAR_LOOPS_END
#endif
