/*
 * Host build of the CUDA C reference's device functions (ref.cu without __CUDACC__), for the
 * offline check of benchmarks/gpu_bench.py: prints Philox words, normal pairs and a few fixed
 * steps, which the script compares with stochpend's Python functions.
 *
 * Usage: host_check SEED H STEPS D TAU OMEGA2
 * Output, one record a line:
 *   kat c0 c1 c2 c3 k0 k1 -> w0 w1 w2 w3           (Random123 known-answer inputs)
 *   normals PATH N z1_f64 z2_f64 z1_f32 z2_f32      (seed SEED)
 *   path PATH x Omega xi                             (float64, after STEPS steps of H)
 */
#include <cstdio>
#include <cstdlib>
#include "ref.cu"

int main(int argc, char **argv)
{
    if (argc != 7) {
        std::fprintf(stderr, "usage: host_check SEED H STEPS D TAU OMEGA2\n");
        return 2;
    }
    u64 seed = std::strtoull(argv[1], nullptr, 10);
    double h = std::atof(argv[2]);
    u64 steps = std::strtoull(argv[3], nullptr, 10);
    double D = std::atof(argv[4]), tau = std::atof(argv[5]), omega2 = std::atof(argv[6]);
    u32 k0 = (u32)seed, k1 = (u32)(seed >> 32);

    const u32 kat[3][6] = {{0u, 0u, 0u, 0u, 0u, 0u},
                           {0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu},
                           {0x243f6a88u, 0x85a308d3u, 0x13198a2eu, 0x03707344u, 0xa4093822u, 0x299f31d0u}};
    for (int i = 0; i < 3; ++i) {
        u32 c[4] = {kat[i][0], kat[i][1], kat[i][2], kat[i][3]};
        philox4x32_10(c, kat[i][4], kat[i][5]);
        std::printf("kat %u %u %u %u %u %u -> %u %u %u %u\n", kat[i][0], kat[i][1], kat[i][2],
                    kat[i][3], kat[i][4], kat[i][5], c[0], c[1], c[2], c[3]);
    }
    const u64 paths[4] = {0ull, 5ull, 123457ull, (1ull << 33) + 7ull};
    for (int p = 0; p < 4; ++p) {
        for (u64 n = 1; n < 4; ++n) {
            double a, b;
            float af, bf;
            normals_f64(k0, k1, paths[p], n, &a, &b);
            normals_f32(k0, k1, paths[p], n, &af, &bf);
            std::printf("normals %llu %llu %.17g %.17g %.9g %.9g\n", paths[p], n, a, b, (double)af,
                        (double)bf);
        }
    }
    OUCoefficients<double> C = ou_coefficients(h, D, tau);
    for (int p = 0; p < 4; ++p) {
        double x, xi, Omega = 0.0;
        init_path(k0, k1, paths[p], D, tau, &x, &xi);
        for (u64 k = 0; k < steps; ++k) {
            double z1, z2;
            normals_f64(k0, k1, paths[p], N_FIRST_STEP + k, &z1, &z2);
            step(&x, &Omega, &xi, h, omega2, C, z1, z2);
        }
        std::printf("path %llu %.17g %.17g %.17g\n", paths[p], x, Omega, xi);
    }
    return 0;
}
