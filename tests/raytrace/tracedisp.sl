/* A displacement that casts a ray: while the ray geometry is being built (on the build's own
 * threads too) it sees nothing, and must not wait for the build it is part of. */
displacement tracedisp(float Km = 0.05)
{
    color c = trace(P, normalize(N));
    P += Km * (0.5 + comp(c, 2)) * normalize(N);
    N = calculatenormal(P);
}
