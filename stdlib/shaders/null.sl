/* RISpec 3.2 Appendix A: null (does nothing) */
surface null()
{
}
