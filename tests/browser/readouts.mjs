// The page's readouts CSV (the Download button's, `web::readouts::ReadoutLog::csv`), parsed the
// one way both browser test files read it: its `#` header, the spacing of its rows as the header
// states it, and the rows as objects keyed by column.
export function parseReadouts(csv) {
  const header = csv.split('\n').filter((l) => l.startsWith('#')).join('\n');
  const every = header.match(/a row every (\d+) active steps/);
  const lines = csv.trim().split('\n').filter((l) => !l.startsWith('#'));
  const columns = lines[0].split(',');
  const rows = lines.slice(1).map((l) => Object.fromEntries(l.split(',').map((v, i) => [columns[i], Number(v)])));
  return { header, rowEvery: every ? Number(every[1]) : NaN, columns, rows };
}
