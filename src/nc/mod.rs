//! The NC language subset: lexer, parser, AST, expressions, `#MSG` formatting, executor.

pub mod ast;
