//! NC expr.
