/* The ray footprint a hit is shaded over: red the square root of area(P), green the width
   of s across it (Du(s)·du + Dv(s)·dv), blue the same of t. */
surface footprint()
{
    Ci = color(sqrt(area(P)), abs(Du(s) * du) + abs(Dv(s) * dv),
               abs(Du(t) * du) + abs(Dv(t) * dv));
    Oi = 1;
}
