/* The compiled floor of the campaign benchmark: one Extended Kalman Filter predict + update of the paper's
 * problem in plain C, the step FilterPy's ExtendedKalmanFilter computes (ekf_floor.py checks that the two agree
 * to 1e-12 before timing this one).
 *
 * State x = [posX, velX, posY, velY, posZ, velZ], covariance P (row-major, as numpy's). Predict: x = F x,
 * P = F P F^T + Q. Update with the ranges to the four beacons and the depth, h(x) = [|p - b_1|, ..., |p - b_4|,
 * posZ] with p = (posX, posY, posZ): H = dh/dx at the predicted state, S = H P H^T + R, the gain K = P H^T S^-1
 * through the Cholesky factor of S, x = x + K (z - h(x)) and P = (I - K H) P (I - K H)^T + K R K^T (FilterPy's
 * Joseph form). Dense loops over whole matrices, no structure of F, H or R used. Built -O2 without
 * vectorization: a straightforward scalar implementation, not a tuned one.
 */
#include <math.h>

#define NX 6
#define NZ 5
#define NB 4

/* C (n x k) = A (n x m) B (m x k), the entry (l, j) of B at B[l * row + j * column]: (k, 1) for B itself,
   (1, m) for B given as its transpose (k x m). */
static void multiply(int n, int m, int k, const double* A, const double* B, int row, int column, double* C) {
    int i, j, l;
    for (i = 0; i < n; i++)
        for (j = 0; j < k; j++) {
            double sum = 0.0;
            for (l = 0; l < m; l++) sum += A[i * m + l] * B[l * row + j * column];
            C[i * k + j] = sum;
        }
}

/* One predict + update of the filter (x, P) in place; 0, or -1 when S is not positive definite. */
int ekf_step(double* x, double* P, const double* F, const double* Q, const double* R, const double* beacons,
             const double* z) {
    double prior[NX], FP[NX * NX], H[NZ * NX], h[NZ], PHt[NX * NZ], S[NZ * NZ], L[NZ * NZ], K[NX * NZ];
    double y[NZ], IKH[NX * NX], T[NX * NX], KR[NX * NZ], KRKt[NX * NX];
    int i, j, l;
    /* predict */
    multiply(NX, NX, 1, F, x, 1, 1, prior);
    multiply(NX, NX, NX, F, P, NX, 1, FP);
    multiply(NX, NX, NX, FP, F, 1, NX, P);
    for (i = 0; i < NX * NX; i++) P[i] += Q[i];
    /* the measurement model and its Jacobian at the prediction */
    for (i = 0; i < NZ * NX; i++) H[i] = 0.0;
    for (i = 0; i < NB; i++) {
        double d[3], r;
        for (j = 0; j < 3; j++) d[j] = prior[2 * j] - beacons[3 * i + j];
        r = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        h[i] = r;
        for (j = 0; j < 3; j++) H[i * NX + 2 * j] = d[j] / r;
    }
    h[NB] = prior[4];
    H[NB * NX + 4] = 1.0;
    /* S = H P H^T + R and its Cholesky factor L (S = L L^T) */
    multiply(NX, NX, NZ, P, H, 1, NX, PHt);
    multiply(NZ, NX, NZ, H, PHt, NZ, 1, S);
    for (i = 0; i < NZ * NZ; i++) S[i] += R[i];
    for (i = 0; i < NZ; i++)
        for (j = 0; j <= i; j++) {
            double sum = S[i * NZ + j];
            for (l = 0; l < j; l++) sum -= L[i * NZ + l] * L[j * NZ + l];
            if (i == j) {
                if (!(sum > 0.0)) return -1;
                L[i * NZ + i] = sqrt(sum);
            } else {
                L[i * NZ + j] = sum / L[j * NZ + j];
            }
        }
    /* K = P H^T S^-1: row i of K solves S k = (P H^T)_i (S symmetric), forward then back substitution */
    for (i = 0; i < NX; i++) {
        double v[NZ];
        for (j = 0; j < NZ; j++) {
            double sum = PHt[i * NZ + j];
            for (l = 0; l < j; l++) sum -= L[j * NZ + l] * v[l];
            v[j] = sum / L[j * NZ + j];
        }
        for (j = NZ - 1; j >= 0; j--) {
            double sum = v[j];
            for (l = j + 1; l < NZ; l++) sum -= L[l * NZ + j] * K[i * NZ + l];
            K[i * NZ + j] = sum / L[j * NZ + j];
        }
    }
    /* the state */
    for (i = 0; i < NZ; i++) y[i] = z[i] - h[i];
    for (i = 0; i < NX; i++) {
        double sum = 0.0;
        for (j = 0; j < NZ; j++) sum += K[i * NZ + j] * y[j];
        x[i] = prior[i] + sum;
    }
    /* the covariance: (I - K H) P (I - K H)^T + K R K^T */
    multiply(NX, NZ, NX, K, H, NX, 1, IKH);
    for (i = 0; i < NX; i++)
        for (j = 0; j < NX; j++) IKH[i * NX + j] = (i == j ? 1.0 : 0.0) - IKH[i * NX + j];
    multiply(NX, NX, NX, IKH, P, NX, 1, T);
    multiply(NX, NX, NX, T, IKH, 1, NX, P);
    multiply(NX, NZ, NZ, K, R, NZ, 1, KR);
    multiply(NX, NZ, NX, KR, K, 1, NZ, KRKt);
    for (i = 0; i < NX * NX; i++) P[i] += KRKt[i];
    return 0;
}

/* `steps` steps of `filters` filters (states xs: filters x NX, covariances Ps: filters x NX x NX), a step of every
   filter after another, as a batch of replicates is stepped; 0, or -1 at the first failed step. */
int ekf_steps(int filters, int steps, double* xs, double* Ps, const double* F, const double* Q, const double* R,
              const double* beacons, const double* z) {
    int k, f;
    for (k = 0; k < steps; k++)
        for (f = 0; f < filters; f++)
            if (ekf_step(xs + f * NX, Ps + f * NX * NX, F, Q, R, beacons, z)) return -1;
    return 0;
}
