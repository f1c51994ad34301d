//! NC lexer.
