//! NC printf.
