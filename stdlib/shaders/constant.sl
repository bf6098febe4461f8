/* RISpec 3.2 Appendix A: constant */
surface constant()
{
    Oi = Os;
    Ci = Os * Cs;
}
