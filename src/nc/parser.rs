//! NC parser.
