//! Statements.

use super::*;

impl Parser<'_> {
    pub(super) fn at_stmt_end(&self) -> bool {
        if self.at_eof() {
            return true;
        }
        if let Tok::Ident(u, _) = self.tok() {
            if STMT_END.contains(&u.as_str()) {
                return true;
            }
            if u == "END_CONFIGURATION" || (TOP.contains(&u.as_str()) && u != "USING") {
                return true;
            }
        }
        self.in_case > 0 && self.looks_like_case_label()
    }

    /// `1, 2..5, Red :` — literals, names, ranges and commas followed by a lone `:`.
    pub(super) fn looks_like_case_label(&self) -> bool {
        let mut i = 0;
        loop {
            match self.tok_at(i) {
                Tok::Colon => return i > 0,
                Tok::Int(_)
                | Tok::Minus
                | Tok::Plus
                | Tok::DotDot
                | Tok::Comma
                | Tok::TypePrefix(..)
                | Tok::Dot => {}
                Tok::Ident(u, _) if !RESERVED.contains(&u.as_str()) => {}
                _ => return false,
            }
            i += 1;
        }
    }

    pub(super) fn stmt_list(&mut self) -> Vec<Stmt> {
        let mut out = Vec::new();
        while !self.at_stmt_end() {
            let before = self.pos;
            match self.stmt() {
                Ok(s) => out.push(s),
                Err(Fail) => {
                    self.recover(STMT_END);
                    if self.pos == before {
                        self.bump();
                    }
                }
            }
        }
        out
    }

    pub(super) fn stmt(&mut self) -> PResult<Stmt> {
        self.guarded("statements", |p| p.stmt_inner())
    }

    /// `IF ... THEN ... ELSIF ... ELSE ... END_IF` after its `IF`.
    fn if_stmt(&mut self) -> PResult<StmtKind> {
        let mut branches = Vec::new();
        let cond = self.expr()?;
        self.expect_kw("THEN")?;
        let body = self.stmt_list();
        branches.push((cond, body));
        let mut else_body = None;
        loop {
            if self.eat_kw("ELSIF") {
                let c = self.expr()?;
                self.expect_kw("THEN")?;
                let b = self.stmt_list();
                branches.push((c, b));
            } else if self.eat_kw("ELSE") {
                else_body = Some(self.stmt_list());
            } else {
                break;
            }
        }
        self.expect_kw("END_IF")?;
        Ok(StmtKind::If {
            branches,
            else_body,
        })
    }

    /// `CASE selector OF labels: ... ELSE ... END_CASE` after its `CASE`.
    fn case_stmt(&mut self) -> PResult<StmtKind> {
        let selector = self.expr()?;
        self.expect_kw("OF")?;
        let mut arms = Vec::new();
        let mut else_body = None;
        self.in_case += 1;
        let r = (|| -> PResult<()> {
            while !self.is_kw("END_CASE") && !self.at_eof() {
                if self.eat_kw("ELSE") {
                    self.in_case -= 1;
                    else_body = Some(self.stmt_list());
                    self.in_case += 1;
                    break;
                }
                let mut labels = Vec::new();
                loop {
                    let a = self.expr()?;
                    if self.eat(&Tok::DotDot) {
                        let b = self.expr()?;
                        labels.push(CaseLabel::Range(a, b));
                    } else {
                        labels.push(CaseLabel::Value(a));
                    }
                    if !self.eat(&Tok::Comma) {
                        break;
                    }
                }
                self.expect(Tok::Colon)?;
                let body = self.stmt_list();
                arms.push(CaseArm { labels, body });
            }
            Ok(())
        })();
        self.in_case -= 1;
        r?;
        self.expect_kw("END_CASE")?;
        Ok(StmtKind::Case {
            selector,
            arms,
            else_body,
        })
    }

    pub(super) fn stmt_inner(&mut self) -> PResult<Stmt> {
        let start = self.span();
        let kind = if self.eat(&Tok::Semi) {
            return Ok(Stmt {
                kind: StmtKind::Empty,
                span: start,
            });
        } else if self.eat_kw("IF") {
            self.if_stmt()?
        } else if self.eat_kw("CASE") {
            self.case_stmt()?
        } else if self.eat_kw("FOR") {
            let var = self.ident()?;
            self.expect(Tok::Assign)?;
            let from = self.expr()?;
            self.expect_kw("TO")?;
            let to = self.expr()?;
            let by = if self.eat_kw("BY") {
                Some(self.expr()?)
            } else {
                None
            };
            self.expect_kw("DO")?;
            let saved = std::mem::take(&mut self.in_case);
            let body = self.stmt_list();
            self.in_case = saved;
            self.expect_kw("END_FOR")?;
            StmtKind::For {
                var,
                from,
                to,
                by,
                body,
            }
        } else if self.eat_kw("WHILE") {
            let cond = self.expr()?;
            self.expect_kw("DO")?;
            let saved = std::mem::take(&mut self.in_case);
            let body = self.stmt_list();
            self.in_case = saved;
            self.expect_kw("END_WHILE")?;
            StmtKind::While { cond, body }
        } else if self.eat_kw("REPEAT") {
            let saved = std::mem::take(&mut self.in_case);
            let body = self.stmt_list();
            self.in_case = saved;
            self.expect_kw("UNTIL")?;
            let until = self.expr()?;
            self.expect_kw("END_REPEAT")?;
            StmtKind::Repeat { body, until }
        } else if self.eat_kw("EXIT") {
            StmtKind::Exit
        } else if self.eat_kw("RETURN") {
            StmtKind::Return
        } else if self.eat_kw("__TRY") {
            let saved = std::mem::take(&mut self.in_case);
            let body = self.stmt_list();
            let mut catch_var = None;
            let mut catch_body = Vec::new();
            let mut finally_body = Vec::new();
            if self.eat_kw("__CATCH") {
                if self.eat(&Tok::LParen) {
                    catch_var = Some(self.ident()?);
                    self.expect(Tok::RParen)?;
                }
                catch_body = self.stmt_list();
            }
            if self.eat_kw("__FINALLY") {
                finally_body = self.stmt_list();
            }
            self.in_case = saved;
            self.expect_kw("__ENDTRY")?;
            StmtKind::Try {
                body,
                catch_var,
                catch_body,
                finally_body,
            }
        } else {
            if let Tok::Ident(u, _) = self.tok()
                && RESERVED.contains(&u.as_str())
                && !matches!(u.as_str(), "THIS" | "SUPER")
            {
                return Err(self.error_here("a statement"));
            }
            let target = self.expr()?;
            if self.eat(&Tok::Assign) {
                let value = self.expr()?;
                StmtKind::Assign { target, value }
            } else if self.is_kw("REF") && matches!(self.tok_at(1), Tok::Eq) {
                self.bump();
                self.bump();
                let value = self.expr()?;
                StmtKind::RefAssign { target, value }
            } else if matches!(target.kind, ExprKind::Call { .. }) {
                StmtKind::Call(target)
            } else {
                return Err(self.error_here("`:=`"));
            }
        };
        let span = start.to(self.prev_span());
        // IEC requires `;` after every statement; CODESYS also accepts a statement that ends
        // with its own keyword (END_IF, END_CASE, END_FOR, END_WHILE, END_REPEAT, __ENDTRY)
        // without one, and so does this parser.
        let ends_with_keyword = matches!(
            kind,
            StmtKind::If { .. }
                | StmtKind::Case { .. }
                | StmtKind::For { .. }
                | StmtKind::While { .. }
                | StmtKind::Repeat { .. }
                | StmtKind::Try { .. }
        );
        if !self.eat(&Tok::Semi) && !ends_with_keyword {
            return Err(self.error_here("`;`"));
        }
        Ok(Stmt { kind, span })
    }
}
