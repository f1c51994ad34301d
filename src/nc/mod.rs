//! The NC language subset: lexer, parser, AST, expressions, `#MSG` formatting, executor.

pub mod ast;
pub mod exec;
pub mod expr;
pub mod lexer;
pub mod parser;
pub mod printf;
