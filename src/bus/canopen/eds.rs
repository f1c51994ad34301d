//! EDS / DCF (CiA 306) electronic data sheets.
