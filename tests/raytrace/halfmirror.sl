/* A mirror reflecting Kr of the light, with trace() inside arithmetic: RISpec's trace is a
 * colour, whatever its sibling operand. */
surface halfmirror(float Kr = 0.5)
{
    normal Nf = faceforward(normalize(N), I);
    Ci = Kr * trace(P, reflect(normalize(I), Nf));
    Oi = 1;
}
