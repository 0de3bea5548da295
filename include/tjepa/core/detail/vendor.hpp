#pragma once
// Eigen and xsimd, first read here. g++ 12 reports a false (maybe-)uninitialized inside its own
// AVX-512 intrinsics once Eigen's or xsimd's double kernels are inlined (GCC bug 105593); the
// diagnostic state that counts is the one where <immintrin.h> is first read, so it is silenced
// around that first read only and users building with -Werror need nothing. (A program that
// includes <immintrin.h>, Eigen or xsimd before tjepa reads them in its own state.)
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#endif
#include <Eigen/Core>
#include <xsimd/xsimd.hpp>
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
