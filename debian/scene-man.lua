-- imuemu-scene(5) from docs/scene-format.md (debian/rules runs pandoc with
-- this filter): a NAME section first, for whatis and apropos, and each table
-- of the document as a list of tagged paragraphs (the key, then one line per
-- column: type, default, range, meaning), which man lays out at any terminal
-- width; groff cannot fit the document's wide tables into 80 columns.

local function cell_inlines(blocks)
  local out = pandoc.List()
  for i, b in ipairs(blocks) do
    if i > 1 then out:insert(pandoc.Space()) end
    if b.t == "Plain" or b.t == "Para" then out:extend(b.content) else out:insert(pandoc.Str(pandoc.utils.stringify(b))) end
  end
  return out
end

function Table(tbl)
  local simple = pandoc.utils.to_simple_table(tbl)
  local names = {}
  for i, h in ipairs(simple.headers) do names[i] = pandoc.utils.stringify(h) end
  local items = pandoc.List()
  for _, row in ipairs(simple.rows) do
    local term = cell_inlines(row[1])
    local paras = pandoc.List()
    for i = 2, #row do
      local content = cell_inlines(row[i])
      if #content > 0 then
        local line = pandoc.List()
        if names[i] ~= "" then line:extend({pandoc.Emph{pandoc.Str(names[i] .. ":")}, pandoc.Space()}) end
        line:extend(content)
        paras:insert(pandoc.Para(line))
      end
    end
    items:insert({term, {paras}})
  end
  return pandoc.DefinitionList(items)
end

function Pandoc(doc)
  local name = {
    pandoc.Header(1, "NAME"),
    pandoc.Para{pandoc.Str("imuemu-scene"), pandoc.Space(), pandoc.Str("-"), pandoc.Space(),
                pandoc.Str("scene files of imuemud, the imuemu IMU emulator service")},
  }
  local blocks = pandoc.List(name)
  blocks:extend(doc.blocks)
  return pandoc.Pandoc(blocks, doc.meta)
end
